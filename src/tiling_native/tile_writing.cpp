// Writing tile files: header and points gathered into one writev per tile (a spilled tile first gets
// its spill file copied in the kernel).
#include "tile_writing.hpp"

#include <fcntl.h>
#include <sys/sendfile.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cstring>
#include <string>
#include <vector>

namespace {

/// Writes every byte of `iov` to `fd`, resuming after partial writes; 0 or an errno.
int writeAll(int fd, iovec* iov, std::size_t count) {
  while (count > 0) {
    const int batch = static_cast<int>(std::min<std::size_t>(count, IOV_MAX));
    ssize_t written = ::writev(fd, iov, batch);
    if (written < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    while (count > 0 && static_cast<std::size_t>(written) >= iov->iov_len) {
      written -= static_cast<ssize_t>(iov->iov_len);
      ++iov;
      --count;
    }
    if (count > 0) {
      iov->iov_base = static_cast<std::uint8_t*>(iov->iov_base) + written;
      iov->iov_len -= static_cast<std::size_t>(written);
    }
  }
  return 0;
}

/// Appends the file `path` to `fd` in the kernel, then deletes it; 0 or an errno.
int appendFile(int fd, const char* path) {
  const int src = ::open(path, O_RDONLY | O_CLOEXEC);
  if (src < 0) return errno;
  struct stat info;
  int error = ::fstat(src, &info) == 0 ? 0 : errno;
  for (off_t offset = 0; error == 0 && offset < info.st_size;) {
    const ssize_t sent = ::sendfile(fd, src, &offset, static_cast<std::size_t>(info.st_size - offset));
    if (sent < 0 && errno != EINTR) error = errno;
    if (sent == 0) error = EIO;  // the spill file shrank under us
  }
  ::close(src);
  if (error == 0 && ::unlink(path) != 0) error = errno;
  return error;
}

/// Binary PCD header of a tile of n points: before_width, n, before_points, n, after_points.
struct TileHeader {
  const char* before_width;
  const char* before_points;
  const char* after_points;
};

/// Where the buffered points of the tiles are (see gpm_write_tiles).
struct TileRows {
  const std::int64_t* begin;
  const std::int64_t* end;
  const std::int64_t* chunk;
  const std::int64_t* first;
  const std::int64_t* last;
  const std::uint8_t* const* chunks;
};

class TileFileWriter {
 public:
  TileFileWriter(int dir_fd, const TileHeader& header, const TileRows& rows)
      : dir_fd_(dir_fd), header_(header), rows_(rows) {}

  /// Writes tile k; 0 or an errno, with the path concerned in *path.
  int write(std::int64_t k, const char* name, const char* spill, std::int64_t count, const char** path) {
    *path = name;
    const int fd = ::openat(dir_fd_, name, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    if (fd < 0) return errno;
    formatHeader(count);
    iov_.clear();
    iov_.push_back(iovec{head_.data(), head_.size()});
    int error = 0;
    if (*spill != '\0') {
      error = writeAll(fd, iov_.data(), iov_.size());
      iov_.clear();
      if (error == 0) {
        error = appendFile(fd, spill);
        if (error != 0) *path = spill;
      }
    }
    for (std::int64_t r = rows_.begin[k]; r < rows_.end[k]; ++r) {
      const std::uint8_t* chunk = rows_.chunks[rows_.chunk[r]];
      iov_.push_back(iovec{const_cast<std::uint8_t*>(chunk + rows_.first[r]),
                           static_cast<std::size_t>(rows_.last[r] - rows_.first[r])});
    }
    if (error == 0) error = writeAll(fd, iov_.data(), iov_.size());
    if (::close(fd) != 0 && error == 0) error = errno;
    return error;
  }

 private:
  void formatHeader(std::int64_t count) {
    const std::string n = std::to_string(count);
    head_.assign(header_.before_width);
    head_ += n;
    head_ += header_.before_points;
    head_ += n;
    head_ += header_.after_points;
  }

  int dir_fd_;
  TileHeader header_;
  TileRows rows_;
  std::string head_;        // reused from tile to tile
  std::vector<iovec> iov_;  // likewise
};

}  // namespace

extern "C" int gpm_write_tiles(int dir_fd, std::int64_t tiles, const char* names, const char* spills,
                               const std::int64_t* counts, const char* before_width, const char* before_points,
                               const char* after_points, const std::int64_t* begin, const std::int64_t* end,
                               const std::int64_t* chunk, const std::int64_t* first, const std::int64_t* last,
                               const std::uint8_t* const* chunks, const char** failed_path) {
  TileFileWriter writer(dir_fd, TileHeader{before_width, before_points, after_points},
                        TileRows{begin, end, chunk, first, last, chunks});
  for (std::int64_t k = 0; k < tiles; ++k) {
    const int error = writer.write(k, names, spills, counts[k], failed_path);
    if (error != 0) return error;
    names += std::strlen(names) + 1;
    spills += std::strlen(spills) + 1;
  }
  return 0;
}
