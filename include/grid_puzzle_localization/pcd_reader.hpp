// Minimal PCD reader for the core tools (ndt_align): x y z of any layout, ascii / binary / binary_compressed.
#pragma once

#include <stdexcept>
#include <string>

#include "grid_puzzle_localization/point_cloud.hpp"

namespace grid_puzzle_localization {

/// Thrown for unreadable or malformed PCD files; the message names the file and the problem.
class PcdReadError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// Reads the x, y, z fields (float32 or float64, any field order and padding) of a PCD v0.7 file. Points with
/// non-finite coordinates are kept (filter them with preprocess()). Throws PcdReadError.
PointCloud readPcdXyz(const std::string& path);

}  // namespace grid_puzzle_localization
