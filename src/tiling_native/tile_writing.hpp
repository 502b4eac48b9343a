// The tiler's write loop (gpm tile, Python): one open, writev and close per tile file, with no Python
// work per tile. A C interface, loaded with ctypes by grid_puzzle_localization.tiling.tile_files; no ROS.
#pragma once

#include <cstdint>

extern "C" {

/// Creates `tiles` new files in the directory `dir_fd`. Tile k is named by the k-th NUL-terminated
/// string of `names` and holds the binary PCD header for n = counts[k] points (the text before_width, n,
/// before_points, n, after_points), then its spill file (the k-th NUL-terminated string of `spills`, empty
/// for none; deleted once copied), then its rows: rows begin[k] .. end[k] - 1, where row r is bytes
/// first[r] .. last[r] - 1 of chunk chunk[r], whose first byte is at chunks[chunk[r]]. Plain arguments
/// only (no structs), so the ctypes caller mirrors no memory layout. Returns 0, or the errno of the first
/// failure, with *failed_path set to the file it concerns (the tile file, or its spill file); the files
/// before it are complete.
int gpm_write_tiles(int dir_fd, std::int64_t tiles, const char* names, const char* spills, const std::int64_t* counts,
                    const char* before_width, const char* before_points, const char* after_points,
                    const std::int64_t* begin, const std::int64_t* end, const std::int64_t* chunk,
                    const std::int64_t* first, const std::int64_t* last, const std::uint8_t* const* chunks,
                    const char** failed_path);
}
