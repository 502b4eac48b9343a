// `python3 -m http.server` for tests and the benchmark: the plain static server a new user tries first (HTTP/1.0,
// a new connection per request, an accept backlog of 5), serving a directory on a free localhost port until stopped.
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <stdexcept>
#include <string>

#include "nginx_server.hpp"

namespace gpl_test {

class PythonHttpServer {
 public:
  /// Serves the files of `root` at http://127.0.0.1:port/ and waits until it accepts connections.
  explicit PythonHttpServer(const std::string& root) : port_(freeLocalPort()) {
    pid_ = ::fork();
    if (pid_ < 0) throw std::runtime_error("fork failed");
    if (pid_ == 0) {
      const int null = ::open("/dev/null", O_WRONLY);  // its log line per request is noise here
      ::dup2(null, 1);
      ::dup2(null, 2);
      const std::string port = std::to_string(port_);
      ::execlp("python3", "python3", "-m", "http.server", "--bind", "127.0.0.1", "--directory", root.c_str(),
               port.c_str(), static_cast<char*>(nullptr));
      ::_exit(127);
    }
    waitUntilAccepting(pid_, port_, "python3 -m http.server", [] { return std::string(); });
  }
  ~PythonHttpServer() {
    ::kill(pid_, SIGTERM);
    int status = 0;
    ::waitpid(pid_, &status, 0);
  }
  PythonHttpServer(const PythonHttpServer&) = delete;
  PythonHttpServer& operator=(const PythonHttpServer&) = delete;

  std::string url(const std::string& path = "") const { return "http://127.0.0.1:" + std::to_string(port_) + path; }

 private:
  int port_ = 0;
  pid_t pid_ = -1;
};

}  // namespace gpl_test
