// The tiler's inner loop (gpm tile, Python): sorting a chunk of PCD records by grid puzzle tile and
// summing up each tile, in one pass over the points instead of a dozen numpy passes. A C interface,
// loaded with ctypes by grid_puzzle_localization.tiling.grouping; no ROS, no dependencies.
#pragma once

#include <cstdint>

extern "C" {

/// Type of a coordinate field: PCD TYPE and SIZE (F4 is float, I2 int16_t, U8 uint64_t, ...).
enum GpmFieldType : std::int32_t { kGpmF4, kGpmF8, kGpmI1, kGpmI2, kGpmI4, kGpmI8, kGpmU1, kGpmU2, kGpmU4, kGpmU8 };

/// One tile of a chunk; the layout of GROUP_DTYPE in grouping.py.
struct GpmTileGroup {
  std::int64_t i, j;      ///< tile index: floor(x / s), floor(y / s), computed in double
  std::int64_t chunk;     ///< left 0 (the caller numbers its chunks)
  std::int64_t start;     ///< first sorted record of the tile
  std::int64_t count;     ///< its number of records
  double min[3], max[3];  ///< bounds of its x, y, z [m]
};

/// Sorts the `n` records of `record_bytes` bytes at `records` by tile (i, j) of side `s`, keeping input
/// order inside a tile, into `sorted` (n records), and writes one group per tile, in (i, j) order, to
/// `groups` (room for n). `offsets` and `types` describe the x, y and z fields; every x, y and z must
/// be finite. `scratch` has room for 2 n int64 values. Returns the number of tiles, or -1 when a tile
/// index would not fit in int64 (a coordinate beyond 2^62 tiles from the origin); then the outputs are
/// unspecified.
std::int64_t gpm_group_by_tile(const std::uint8_t* records, std::int64_t n, std::int64_t record_bytes,
                               const std::int64_t* offsets, const std::int32_t* types, double s, std::uint8_t* sorted,
                               GpmTileGroup* groups, std::int64_t* scratch);
}
