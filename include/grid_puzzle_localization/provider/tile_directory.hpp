// Which tiles a tile directory holds, from its index.json (read as a stream: no document in memory) or by scanning
// the <cx>_<cy>.pcd names; the C++ twin of src/grid_puzzle_localization/tiles/directory.py and tiles/grid.py's names.
// The tiles are kept as runs of consecutive j per row i, so the memory follows the map's outline, not its area: the
// provider nodelet lives in the localizer's process, whose memory must not grow with the map. No ROS.
#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "grid_puzzle_localization/provider/window.hpp"
#include "grid_puzzle_localization/voxel_map.hpp"

namespace grid_puzzle_localization {

/// One code per tile index, ordered as (i, j) pairs are; throws std::out_of_range beyond +-2^31.
std::uint64_t encodeTileKey(std::int64_t i, std::int64_t j);
TileKey decodeTileKey(std::uint64_t code);

/// Decimal text of the centre of tile `i` of side `s` [m]: the fewest fractional digits (1 to 17) within s * 1e-9
/// of the exact centre (the README's tile format).
std::string formatTileCentre(std::int64_t i, double s);
/// File stem "cx_cy" of tile (i, j).
std::string tileStem(std::int64_t i, std::int64_t j, double s);
/// Tile (i, j) of an exact stem "cx_cy" of side `s`; false when `stem` is not the name of such a tile.
bool parseTileStem(const std::string& stem, double s, TileKey& key);

/// Identity of a directory's contents: its index file's inode, time and size, else the directory's own.
std::string tileIndexRevision(const std::string& dir);

/// A set of tiles as runs [j_first, j_last] of consecutive tiles per row i (rows by i, runs by j). A solid square
/// map of a million tiles takes a thousand runs. Built from keys in (i, j) order.
class TileRuns {
 public:
  /// Adds a tile after every tile added so far in (i, j) order; false (nothing added) when it is not after them.
  bool append(std::int64_t i, std::int64_t j);
  /// Codes (encodeTileKey) of the tiles inside `box`, in (i, j) order, appended to `out`.
  void codesInBox(const TileBox& box, std::vector<std::uint64_t>& out) const;
  std::size_t size() const { return size_; }
  std::size_t runCount() const { return runs_.size(); }
  bool empty() const { return size_ == 0; }
  /// Over all tiles; not when empty().
  TileBox bounds() const;

 private:
  struct Run {
    std::int64_t j_first, j_last;
  };
  std::vector<std::int64_t> row_i_;     // i of each row
  std::vector<std::size_t> row_first_;  // index in runs_ of each row's first run
  std::vector<Run> runs_;
  std::size_t size_ = 0;
};

class RemoteTileIndex;

struct TileDirectory {
  std::string path;                     ///< a local directory, or the URL of a map store
  double grid_size = 0.0;               ///< s [m]
  TileRuns tiles;                       ///< every tile of the directory
  std::string source;                   ///< "index" or "scan"
  std::vector<std::string> unparsable;  ///< *.pcd names that are not tiles of side s (scan only)
  TileBox bounds;                       ///< over all tiles
  /// Set for a directory given by URL: the newest index its poller fetched (refresh() takes it from there).
  std::shared_ptr<RemoteTileIndex> remote;

  std::string tilePath(const TileKey& key) const { return path + "/" + tileStem(key.i, key.j, grid_size) + ".pcd"; }
};

/// One tile as index.json lists it: what a copy of the file fetched from elsewhere (the HTTP map store) is checked
/// against before it is used.
struct TileIndexEntry {
  std::string file;         ///< file name in the directory, e.g. "1.0_-3.0.pcd" (as the index says: not validated)
  std::uint64_t bytes = 0;  ///< file size [bytes]
  std::string sha256;       ///< SHA-256 of the file, 64 lowercase hex digits; empty in an index written without them
};

/// What an index.json says, parsed from its text (`gpm tile`'s schema, src/grid_puzzle_localization/tiling/index.py).
struct TileIndexListing {
  double grid_size = 0.0;             ///< s [m]
  std::vector<TileIndexEntry> tiles;  ///< in the index's order
  TileRuns keys;                      ///< every tile's key
  bool checksums() const { return !tiles.empty() && !tiles.front().sha256.empty(); }
};

/// Parses the text of an index.json; `what` (its path or URL) names it in the error. Old indexes without `sha256`
/// are accepted; an index with `sha256` on some tiles only, or one that is not 64 lowercase hex digits, is not.
/// Throws std::invalid_argument naming `what` and the problem.
TileIndexListing parseTileIndex(const std::string& text, const std::string& what);

/// The tile directory at `url` that `listing` (its index.json) describes; `grid_size` [m] as for openTileDirectory.
/// Throws std::invalid_argument naming the URL when the sizes disagree or the index lists no tiles.
TileDirectory tileDirectoryOfIndex(const std::string& url, const TileIndexListing& listing, double grid_size);

/// The newest index of a tile directory given by URL and its revision, handed from the thread that polls the server
/// (outside any lock the provider's window holds) to the window's tile references. Thread-safe.
class RemoteTileIndex {
 public:
  void set(TileDirectory directory, std::string revision) {
    std::lock_guard<std::mutex> lock(mutex_);
    directory_ = std::move(directory);
    revision_ = std::move(revision);
  }
  std::string revision() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return revision_;
  }
  /// The directory and its revision when that is not `known`.
  std::optional<std::pair<TileDirectory, std::string>> newerThan(const std::string& known) const {
    std::lock_guard<std::mutex> lock(mutex_);
    if (revision_ == known) return std::nullopt;
    return std::make_pair(directory_, revision_);
  }

 private:
  mutable std::mutex mutex_;
  TileDirectory directory_;
  std::string revision_;
};

/// Opens `path` through its index.json, or by scanning it when there is none. `grid_size` [m]: 0 takes the index's;
/// required without an index and must match the index when both are given. Throws std::invalid_argument naming the
/// directory and what to do when it is missing, unreadable or holds no tiles.
TileDirectory openTileDirectory(const std::string& path, double grid_size);

}  // namespace grid_puzzle_localization
