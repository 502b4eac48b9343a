// The map store's disk cache: files in one directory, the least recently used evicted first once their bytes pass a
// budget. Every file is written to a temporary name and renamed into place, so a reader (or a crash) never sees half
// a file; the recency is the files' modification time, touched on use, so the order survives a restart. The store
// checks every file against the index before it uses it, so a file damaged on disk is caught and fetched again.
// Not thread-safe (one owner). No ROS.
#pragma once

#include <cstdint>
#include <list>
#include <string>
#include <unordered_map>
#include <unordered_set>

namespace grid_puzzle_localization {
namespace map_store_detail {

class DiskCache {
 public:
  /// Opens (creates) `dir`, drops temporary files a crash left behind, and evicts down to `budget` bytes.
  /// Throws std::invalid_argument naming the directory when it cannot be created or read.
  DiskCache(std::string dir, std::uint64_t budget);

  std::string pathOf(const std::string& name) const { return dir_ + "/" + name; }
  /// True when `name` is cached; it becomes the most recently used.
  bool touch(const std::string& name);
  /// Writes `bytes` as `name` atomically; throws std::runtime_error naming the file when it cannot.
  void store(const std::string& name, const std::string& bytes);
  void remove(const std::string& name);
  /// Keeps `name` until unpinAll() whatever the budget (a file handed out and not yet read).
  void pin(const std::string& name) { pinned_.insert(name); }
  void unpinAll() { pinned_.clear(); }
  /// Evicts the least recently used unpinned files until the budget holds (or only pinned ones are left).
  void evict();
  std::uint64_t bytes() const { return bytes_; }
  const std::string& directory() const { return dir_; }

 private:
  struct Entry {
    std::string name;
    std::uint64_t bytes;
  };
  std::string dir_;
  std::uint64_t budget_;
  std::uint64_t bytes_ = 0;
  std::list<Entry> lru_;  // least recently used first
  std::unordered_map<std::string, std::list<Entry>::iterator> index_;
  std::unordered_set<std::string> pinned_;
};

/// Writes `bytes` to `path` through a temporary file in the same directory and a rename.
void writeFileAtomically(const std::string& path, const std::string& bytes);
/// The whole file, or false when it cannot be read.
bool readWholeFile(const std::string& path, std::string& bytes);
/// Creates `path` and its parents (mode 0755); throws std::invalid_argument naming it.
void makeDirectories(const std::string& path);

}  // namespace map_store_detail
}  // namespace grid_puzzle_localization
