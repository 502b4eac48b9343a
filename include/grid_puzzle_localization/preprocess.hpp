// Scan preprocessing for the localizer: range crop, NaN/origin removal, voxel downsampling.
#pragma once

#include <cstddef>
#include <string>

#include "grid_puzzle_localization/point_cloud.hpp"

namespace grid_puzzle_localization {

struct PreprocessConfig {
  double min_range = 1.0;    ///< [m] points closer to the sensor are dropped (robot body, ghost returns)
  double max_range = 100.0;  ///< [m] points farther away are dropped
  double voxel_size = 0.5;   ///< [m] leaf of the centroid voxel filter; 0 disables downsampling

  /// Returns an empty string when the values are usable, otherwise a message naming the bad value.
  std::string validate() const;
};

struct PreprocessReport {
  std::size_t input = 0;         ///< points given
  std::size_t non_finite = 0;    ///< dropped: NaN or inf coordinate
  std::size_t at_origin = 0;     ///< dropped: exactly (0, 0, 0), a sensor's "no return"
  std::size_t out_of_range = 0;  ///< dropped by the range crop
  std::size_t output = 0;        ///< points returned
};

/// Filters `input` (sensor frame, metres) into a new cloud. The voxel filter replaces the points of
/// each occupied world-aligned voxel by their centroid, in order of first appearance, so the result is
/// deterministic. Throws std::invalid_argument when `config` does not validate.
PointCloud preprocess(const PointCloud& input, const PreprocessConfig& config, PreprocessReport* report = nullptr);

/// Centroid voxel filter alone (leaf in metres, > 0).
PointCloud voxelDownsample(const PointCloud& input, double leaf);

}  // namespace grid_puzzle_localization
