// Scan preprocessing for the localizer: range crop, NaN/origin removal, voxel downsampling.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "grid_puzzle_localization/deskew.hpp"
#include "grid_puzzle_localization/point_cloud.hpp"
#include "grid_puzzle_localization/voxel_map.hpp"

namespace grid_puzzle_localization {

struct PreprocessConfig {
  double min_range = 1.0;    ///< [m] points closer to the sensor are dropped (robot body, ghost returns)
  double max_range = 100.0;  ///< [m] points farther away are dropped
  double voxel_size = 0.5;   ///< [m] leaf of the centroid voxel filter; 0 disables downsampling
  /// Move the points of a scan that carries per-point times to the scan stamp (after the range crop, before
  /// the voxel filter, so the robot body is still cropped and voxels average deskewed points).
  bool deskew = true;
  /// [s] >= 0: time constant of the low-pass filter on the twist that deskews scans (used by the localizer).
  /// The twist is the difference of two matched poses, and each matched pose depends on the twist its scan was
  /// deskewed with: unfiltered (0), that loop is marginally stable and the speed oscillates scan to scan.
  double deskew_twist_smoothing = 0.15;

  /// Returns an empty string when the values are usable, otherwise a message naming the bad value.
  std::string validate() const;
};

struct PreprocessReport {
  std::size_t input = 0;         ///< points given
  std::size_t non_finite = 0;    ///< dropped: NaN or inf coordinate
  std::size_t at_origin = 0;     ///< dropped: exactly (0, 0, 0), a sensor's "no return"
  std::size_t out_of_range = 0;  ///< dropped by the range crop
  std::size_t output = 0;        ///< points returned
  bool deskewed = false;         ///< the kept points were moved to the scan stamp
};

/// Centroid voxel filter: the points of each occupied world-aligned voxel (leaf in metres) are replaced by
/// their centroid, in order of first appearance, so the result is deterministic. Its hash table and sums
/// are kept between calls, so a steady stream of scans allocates nothing. Not thread-safe.
class VoxelCentroidFilter {
 public:
  /// Filters `input` into `out` (its previous content is replaced; not `input` itself). Throws
  /// std::invalid_argument unless leaf > 0.
  void apply(const PointCloud& input, double leaf, PointCloud& out);

 private:
  struct Slot {
    VoxelKey key;
    std::int32_t voxel = -1;  ///< index into sums_/counts_, -1 = empty
  };
  std::vector<Slot> slots_;  ///< open addressing, power-of-two size, load <= 0.5; all empty between calls
  std::vector<std::size_t> used_slots_;
  std::vector<Eigen::Vector3d> sums_;
  std::vector<std::size_t> counts_;
};

/// Preprocessing of a stream of scans with buffers reused between scans (scan thread only).
class Preprocessor {
 public:
  /// Throws std::invalid_argument when `config` does not validate.
  explicit Preprocessor(const PreprocessConfig& config);
  /// Filters `input` (sensor frame, metres) into `out` (its previous content is replaced; not `input` itself).
  /// With `times` (one per input point, [s] after the stamp) and `motion`, and config.deskew, the kept points
  /// are deskewed. Throws std::invalid_argument when `times` has another size than `input`.
  void apply(const PointCloud& input, PointCloud& out, PreprocessReport* report = nullptr,
             const PointTimes* times = nullptr, const SweepMotion* motion = nullptr);

 private:
  PreprocessConfig config_;
  PointCloud kept_;
  PointTimes kept_times_;
  VoxelCentroidFilter voxel_filter_;
};

/// One-off preprocessing into a new cloud (Preprocessor with fresh buffers). Throws std::invalid_argument when
/// `config` does not validate.
PointCloud preprocess(const PointCloud& input, const PreprocessConfig& config, PreprocessReport* report = nullptr);

/// One-off centroid voxel filter (leaf in metres, > 0).
PointCloud voxelDownsample(const PointCloud& input, double leaf);

}  // namespace grid_puzzle_localization
