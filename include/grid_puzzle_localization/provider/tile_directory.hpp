// Which tiles a tile directory holds, from its index.json (read as a stream: no document in memory) or by scanning
// the <cx>_<cy>.pcd names; the C++ twin of src/grid_puzzle_localization/tiles/directory.py and tiles/grid.py's names.
// Keys are one sorted array of 64-bit codes, so a window query is two binary searches per row of tiles. No ROS.
#pragma once

#include <cstdint>
#include <string>
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

struct TileDirectory {
  std::string path;
  double grid_size = 0.0;               ///< s [m]
  std::vector<std::uint64_t> codes;     ///< encodeTileKey of every tile, sorted
  std::string source;                   ///< "index" or "scan"
  std::vector<std::string> unparsable;  ///< *.pcd names that are not tiles of side s (scan only)
  TileBox bounds;                       ///< over all tiles

  std::string tilePath(const TileKey& key) const { return path + "/" + tileStem(key.i, key.j, grid_size) + ".pcd"; }
  /// Codes of the tiles inside `box`, sorted (appended to `out`).
  void codesInBox(const TileBox& box, std::vector<std::uint64_t>& out) const;
};

/// Opens `path` through its index.json, or by scanning it when there is none. `grid_size` [m]: 0 takes the index's;
/// required without an index and must match the index when both are given. Throws std::invalid_argument naming the
/// directory and what to do when it is missing, unreadable or holds no tiles.
TileDirectory openTileDirectory(const std::string& path, double grid_size);

}  // namespace grid_puzzle_localization
