// Flat per-scan diagnostics of the localizer, free of the NDT headers so that code which also includes
// the generated NdtStatus message (same namespace as the core's NdtStatus enum) can use it. No ROS.
#pragma once

#include <cstddef>
#include <string>

namespace grid_puzzle_localization {

struct MatchSummary {
  bool converged = false;
  bool match_accepted = false;  ///< false: the prediction was used
  int iterations = 0;
  double score = 0.0;                       ///< NDT cost, <= 0, lower is better
  double transformation_probability = 0.0;  ///< -score / source points
  double nvtl = 0.0;                        ///< nearest voxel transformation likelihood
  double inlier_fraction = 0.0;             ///< [0, 1]
  double align_ms = 0.0;
  double target_update_ms = 0.0;  ///< last background target update
  std::size_t target_voxels = 0;
  std::size_t target_points = 0;
  std::size_t source_points = 0;
  std::string ndt_status;  ///< the NDT result status as text (OK, MAX_ITERATIONS, ...)
};

}  // namespace grid_puzzle_localization
