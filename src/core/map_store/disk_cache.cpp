#include "disk_cache.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <openssl/evp.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <tuple>
#include <vector>

#include "grid_puzzle_localization/map_store/map_store.hpp"

namespace grid_puzzle_localization {
namespace map_store_detail {
namespace {

constexpr const char* kTempPrefix = ".tmp-";

std::string errnoText() { return std::strerror(errno); }

}  // namespace

void makeDirectories(const std::string& path) {
  for (std::size_t pos = 1; pos != std::string::npos;) {
    pos = path.find('/', pos + 1);
    const std::string part = path.substr(0, pos);
    if (::mkdir(part.c_str(), 0755) != 0 && errno != EEXIST)
      throw std::invalid_argument("map store cache directory " + part + " cannot be created (" + errnoText() +
                                  "); set map_store/cache_dir to a writable directory");
  }
}

void writeFileAtomically(const std::string& path, const std::string& bytes) {
  static std::atomic<unsigned> counter{0};
  const std::size_t slash = path.rfind('/');
  const std::string temp = path.substr(0, slash + 1) + kTempPrefix + std::to_string(::getpid()) + "-" +
                           std::to_string(counter++) + "-" + path.substr(slash + 1);
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) throw std::runtime_error("cannot create " + temp + ": " + errnoText());
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string why = errnoText();
      ::close(fd);
      ::unlink(temp.c_str());
      throw std::runtime_error("cannot write " + temp + ": " + why);
    }
    done += static_cast<std::size_t>(n);
  }
  if (::close(fd) != 0 || ::rename(temp.c_str(), path.c_str()) != 0) {
    const std::string why = errnoText();
    ::unlink(temp.c_str());
    throw std::runtime_error("cannot store " + path + ": " + why);
  }
}

bool readWholeFile(const std::string& path, std::string& bytes) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  struct stat st {};
  bool ok = ::fstat(fd, &st) == 0;
  bytes.assign(ok ? static_cast<std::size_t>(st.st_size) : 0, '\0');
  std::size_t done = 0;
  while (ok && done < bytes.size()) {
    const ssize_t n = ::read(fd, &bytes[done], bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) ok = false;
    done += n > 0 ? static_cast<std::size_t>(n) : 0;
  }
  ::close(fd);
  return ok;
}

}  // namespace map_store_detail

std::string sha256Hex(const std::string& bytes) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int size = 0;
  if (EVP_Digest(bytes.data(), bytes.size(), digest, &size, EVP_sha256(), nullptr) != 1)
    throw std::runtime_error("SHA-256 failed (OpenSSL EVP_Digest)");
  static const char* kHex = "0123456789abcdef";
  std::string hex(2 * size, '0');
  for (unsigned int k = 0; k < size; ++k) {
    hex[2 * k] = kHex[digest[k] >> 4];
    hex[2 * k + 1] = kHex[digest[k] & 15];
  }
  return hex;
}

namespace map_store_detail {

DiskCache::DiskCache(std::string dir, std::uint64_t budget) : dir_(std::move(dir)), budget_(budget) {
  makeDirectories(dir_);
  DIR* d = ::opendir(dir_.c_str());
  if (d == nullptr) throw std::invalid_argument("map store cache directory " + dir_ + " cannot be read");
  std::vector<std::tuple<std::int64_t, std::string, std::uint64_t>> found;  // mtime [ns], name, bytes
  while (const dirent* entry = ::readdir(d)) {
    const std::string name = entry->d_name;
    if (name == "." || name == "..") continue;
    const std::string path = pathOf(name);
    if (name.compare(0, std::strlen(kTempPrefix), kTempPrefix) == 0) {
      // A write a crash interrupted; a live process's (another store on this directory) is left alone.
      const long pid = std::strtol(name.c_str() + std::strlen(kTempPrefix), nullptr, 10);
      if (pid <= 0 || (pid != ::getpid() && ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH))
        ::unlink(path.c_str());
      continue;
    }
    struct stat st {};
    if (::stat(path.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) continue;
    found.emplace_back(static_cast<std::int64_t>(st.st_mtim.tv_sec) * 1000000000LL + st.st_mtim.tv_nsec, name,
                       static_cast<std::uint64_t>(st.st_size));
  }
  ::closedir(d);
  std::sort(found.begin(), found.end());
  for (auto& [mtime, name, size] : found) {
    lru_.push_back({name, size});
    index_[name] = std::prev(lru_.end());
    bytes_ += size;
  }
  evict();
}

bool DiskCache::touch(const std::string& name) {
  const auto it = index_.find(name);
  if (it == index_.end()) return false;
  lru_.splice(lru_.end(), lru_, it->second);
  ::utimensat(AT_FDCWD, pathOf(name).c_str(), nullptr, 0);  // now: the order survives a restart
  return true;
}

void DiskCache::store(const std::string& name, const std::string& bytes) {
  writeFileAtomically(pathOf(name), bytes);
  const auto it = index_.find(name);
  if (it != index_.end()) {
    bytes_ -= it->second->bytes;
    lru_.erase(it->second);
  }
  lru_.push_back({name, bytes.size()});
  index_[name] = std::prev(lru_.end());
  bytes_ += bytes.size();
}

void DiskCache::remove(const std::string& name) {
  ::unlink(pathOf(name).c_str());
  const auto it = index_.find(name);
  if (it == index_.end()) return;
  bytes_ -= it->second->bytes;
  lru_.erase(it->second);
  index_.erase(it);
}

void DiskCache::evict() {
  for (auto it = lru_.begin(); bytes_ > budget_ && it != lru_.end();) {
    if (pinned_.count(it->name)) {
      ++it;
      continue;
    }
    ::unlink(pathOf(it->name).c_str());
    bytes_ -= it->bytes;
    index_.erase(it->name);
    it = lru_.erase(it);
  }
}

}  // namespace map_store_detail
}  // namespace grid_puzzle_localization
