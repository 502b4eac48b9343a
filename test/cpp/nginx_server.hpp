// A real nginx for tests: writes its own nginx.conf into a temporary directory, listens on a free localhost port,
// runs without root (pid file, logs and temp paths in that directory; one process, no daemon) and is stopped by the
// test. `NginxServer::binary()` is "" when nginx is not installed (tools/apt-packages.txt installs nginx-light).
#pragma once

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>

namespace gpl_test {

/// A localhost TCP port nothing listens on now.
inline int freeLocalPort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t size = sizeof(addr);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &size) != 0)
    throw std::runtime_error("no free port");
  ::close(fd);
  return ntohs(addr.sin_port);
}

/// True when something accepts connections on localhost `port`.
inline bool acceptsOn(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<std::uint16_t>(port));
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0;
  ::close(fd);
  return ok;
}

/// Waits until the server process `pid` accepts connections on `port`; throws, naming `name` and `detail()`, when it
/// exits first (then sets `pid` to -1) or does not within 10 s.
template <typename Detail>
void waitUntilAccepting(pid_t& pid, int port, const std::string& name, Detail detail) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (!acceptsOn(port)) {
    int status = 0;
    if (::waitpid(pid, &status, WNOHANG) == pid) {
      pid = -1;
      throw std::runtime_error(name + " exited at start-up" + detail());
    }
    if (std::chrono::steady_clock::now() > deadline) throw std::runtime_error(name + " did not start" + detail());
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

class NginxServer {
 public:
  /// The nginx binary on PATH or in /usr/sbin, "" when there is none.
  static std::string binary() {
    std::string dirs = std::string(std::getenv("PATH") ? std::getenv("PATH") : "") + ":/usr/sbin:/sbin";
    std::stringstream in(dirs);
    for (std::string dir; std::getline(in, dir, ':');)
      if (!dir.empty() && ::access((dir + "/nginx").c_str(), X_OK) == 0) return dir + "/nginx";
    return "";
  }

  /// Serves the files of `root` at http://127.0.0.1:port/; `extra` is added inside the server block (locations).
  /// Not started yet: start().
  NginxServer(std::string root, std::string extra = "") : root_(std::move(root)), extra_(std::move(extra)) {
    char tmpl[] = "/tmp/gpl_nginx_XXXXXX";
    if (::mkdtemp(tmpl) == nullptr) throw std::runtime_error("mkdtemp failed");
    dir_ = tmpl;
    port_ = freeLocalPort();
  }
  ~NginxServer() {
    stop();
    std::system(("rm -rf '" + dir_ + "'").c_str());
  }
  NginxServer(const NginxServer&) = delete;
  NginxServer& operator=(const NginxServer&) = delete;

  int port() const { return port_; }
  std::string url(const std::string& path = "") const { return "http://127.0.0.1:" + std::to_string(port_) + path; }
  const std::string& directory() const { return dir_; }

  /// Starts nginx (again on the same port after stop()) and waits until it accepts connections.
  void start() {
    writeConfig();
    pid_ = ::fork();
    if (pid_ < 0) throw std::runtime_error("fork failed");
    if (pid_ == 0) {
      const int out = ::open((dir_ + "/stderr.log").c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
      ::dup2(out, 1);
      ::dup2(out, 2);
      const std::string bin = binary(), conf = dir_ + "/nginx.conf", prefix = dir_ + "/";
      ::execl(bin.c_str(), bin.c_str(), "-c", conf.c_str(), "-p", prefix.c_str(), static_cast<char*>(nullptr));
      ::_exit(127);
    }
    waitUntilAccepting(pid_, port_, "nginx", [this] { return ": " + log(); });
  }

  /// Stops nginx (SIGTERM: it closes its connections at once) and waits for it.
  void stop() {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGTERM);
    int status = 0;
    ::waitpid(pid_, &status, 0);
    pid_ = -1;
  }

  std::string log() const {
    std::ifstream a(dir_ + "/stderr.log"), b(dir_ + "/error.log");
    std::stringstream s;
    s << a.rdbuf() << b.rdbuf();
    return s.str();
  }

 private:
  void writeConfig() const {
    std::ofstream conf(dir_ + "/nginx.conf");
    // As root, nginx would switch to "nobody", who cannot read a test's private temporary directory.
    if (::geteuid() == 0) conf << "user root root;\n";
    conf << "daemon off;\nmaster_process off;\nworker_processes 1;\n"
         << "pid " << dir_ << "/nginx.pid;\nerror_log " << dir_ << "/error.log warn;\n"
         << "events { worker_connections 64; }\n"
         << "http {\n  access_log off;\n  default_type application/octet-stream;\n"
         << "  types { application/json json; }\n  keepalive_timeout 30;\n"
         << "  client_body_temp_path " << dir_ << "/client_body;\n  proxy_temp_path " << dir_ << "/proxy;\n"
         << "  fastcgi_temp_path " << dir_ << "/fastcgi;\n  uwsgi_temp_path " << dir_ << "/uwsgi;\n"
         << "  scgi_temp_path " << dir_ << "/scgi;\n"
         << "  server {\n    listen 127.0.0.1:" << port_ << ";\n    root " << root_ << ";\n"
         << extra_ << "\n  }\n}\n";
  }

  std::string root_, extra_, dir_;
  int port_ = 0;
  pid_t pid_ = -1;
};

}  // namespace gpl_test
