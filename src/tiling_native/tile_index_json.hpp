// The tiles array of a tile index (index.json, written by gpm tile in Python): the text of a batch of
// tiles formatted in one call, floats exactly as Python's repr writes them (as json.dumps does). A C
// interface, loaded with ctypes by grid_puzzle_localization.tiling.index; no ROS.
#pragma once

#include <cstdint>

extern "C" {

/// Columns of `tiles` tiles: key i, j; file name (NUL-terminated, back to back); point count; file
/// size; bounds, as columns x, y, z of their minimum and of their maximum [m].
struct GpmTileColumns {
  const std::int64_t* i;
  const std::int64_t* j;
  const char* files;
  const std::int64_t* points;
  const std::int64_t* bytes;
  const double* lower[3];
  const double* upper[3];
};

/// Writes the tiles as JSON objects separated by commas (the schema in tiling/index.py) to `out`,
/// with centres (i + 1/2) s and data bytes points * record_bytes. Returns the length written, or -1
/// when that would be more than `capacity` bytes.
std::int64_t gpm_tiles_json(std::int64_t tiles, const GpmTileColumns* columns, double grid_size,
                            std::int64_t record_bytes, char* out, std::int64_t capacity);
}
