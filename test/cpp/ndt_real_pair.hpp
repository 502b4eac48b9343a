// The real HDL-32E pair (test/data/hdl32_pair) prepared the customary way, for tests and the benchmark.
#pragma once

#include <fstream>
#include <stdexcept>
#include <string>

#include "grid_puzzle_localization/pcd_reader.hpp"
#include "grid_puzzle_localization/preprocess.hpp"

namespace grid_puzzle_localization {
namespace real_pair {

inline std::string dataDir() { return std::string(GPL_SOURCE_DIR) + "/test/data/hdl32_pair"; }

/// Drops (0, 0, 0) points, then a 0.1 m centroid voxel filter (no range crop).
inline PointCloud load(const std::string& name) {
  PreprocessConfig cfg;
  cfg.min_range = 0.0;
  cfg.max_range = 1e9;
  cfg.voxel_size = 0.1;
  return preprocess(readPcdXyz(dataDir() + "/" + name), cfg);
}

inline PointCloud target() { return load("251370668.pcd"); }
inline PointCloud source() { return load("251371071.pcd"); }

/// A 4x4 whitespace-separated matrix file (the reference T_target_source).
inline Eigen::Matrix4d readMatrix(const std::string& name) {
  std::ifstream in(dataDir() + "/" + name);
  if (!in) throw std::runtime_error("cannot open " + dataDir() + "/" + name);
  Eigen::Matrix4d m;
  for (int i = 0; i < 16; ++i)
    if (!(in >> m(i / 4, i % 4))) throw std::runtime_error("malformed matrix in " + name);
  return m;
}

inline Eigen::Matrix4d reference() { return readMatrix("relative_fast_gicp.txt"); }

}  // namespace real_pair
}  // namespace grid_puzzle_localization
