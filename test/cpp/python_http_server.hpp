// Python servers on a free localhost port for tests and the benchmark, each a child process until destroyed:
// - PythonHttpServer: `python3 -m http.server`, the plain static server a new user tries first (HTTP/1.0, a new
//   connection per request, an accept backlog of 5), serving a directory;
// - DelayProxyServer: bench/delay_proxy.py in front of another localhost server, at most so many requests a second
//   (a slow map store).
#pragma once

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "nginx_server.hpp"

namespace gpl_test {

class PythonServer {
 public:
  /// Runs `python3 args...` (which must serve on port()) and waits until it accepts connections; `what` names it in
  /// errors.
  PythonServer(const std::vector<std::string>& args, int port, const std::string& what) : port_(port) {
    pid_ = ::fork();
    if (pid_ < 0) throw std::runtime_error("fork failed");
    if (pid_ == 0) {
      const int null = ::open("/dev/null", O_WRONLY);  // a log line per request is noise here
      ::dup2(null, 1);
      ::dup2(null, 2);
      std::vector<char*> argv{const_cast<char*>("python3")};
      for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      ::execvp("python3", argv.data());
      ::_exit(127);
    }
    waitUntilAccepting(pid_, port_, what, [] { return std::string(); });
  }
  ~PythonServer() {
    ::kill(pid_, SIGTERM);
    int status = 0;
    ::waitpid(pid_, &status, 0);
  }
  PythonServer(const PythonServer&) = delete;
  PythonServer& operator=(const PythonServer&) = delete;

  int port() const { return port_; }
  std::string url(const std::string& path = "") const { return "http://127.0.0.1:" + std::to_string(port_) + path; }

 private:
  int port_ = 0;
  pid_t pid_ = -1;
};

/// Serves the files of `root` at http://127.0.0.1:port/.
class PythonHttpServer : public PythonServer {
 public:
  explicit PythonHttpServer(const std::string& root, int port = freeLocalPort())
      : PythonServer({"-m", "http.server", "--bind", "127.0.0.1", "--directory", root, std::to_string(port)}, port,
                     "python3 -m http.server") {}
};

/// Passes requests on to 127.0.0.1:`upstream_port`, at most `requests_per_second` a second over all connections
/// (bench/delay_proxy.py, found through GPL_SOURCE_DIR).
class DelayProxyServer : public PythonServer {
 public:
  DelayProxyServer(int upstream_port, double requests_per_second, int port = freeLocalPort())
      : PythonServer({std::string(GPL_SOURCE_DIR) + "/bench/delay_proxy.py", std::to_string(upstream_port), "--port",
                      std::to_string(port), "--requests-per-second", number(requests_per_second)},
                     port, "bench/delay_proxy.py") {}

 private:
  static std::string number(double value) {
    std::ostringstream s;
    s << value;
    return s.str();
  }
};

}  // namespace gpl_test
