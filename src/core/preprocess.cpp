#include "grid_puzzle_localization/preprocess.hpp"

#include <cmath>
#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <unordered_map>

namespace grid_puzzle_localization {
namespace {

struct VoxelKeyHash {
  std::size_t operator()(const Eigen::Vector3i& k) const noexcept {
    // Large odd multipliers spread neighbouring integer keys across buckets.
    const auto x = static_cast<std::uint64_t>(static_cast<std::uint32_t>(k.x()));
    const auto y = static_cast<std::uint64_t>(static_cast<std::uint32_t>(k.y()));
    const auto z = static_cast<std::uint64_t>(static_cast<std::uint32_t>(k.z()));
    return static_cast<std::size_t>((x * 73856093ULL) ^ (y * 19349663ULL) ^ (z * 83492791ULL));
  }
};

struct VoxelKeyEqual {
  bool operator()(const Eigen::Vector3i& a, const Eigen::Vector3i& b) const noexcept { return a == b; }
};

}  // namespace

std::string PreprocessConfig::validate() const {
  std::ostringstream err;
  if (!(min_range >= 0.0)) err << "min_range must be >= 0 m (got " << min_range << "); ";
  if (!(max_range > min_range)) err << "max_range must be > min_range (got " << max_range << " m); ";
  if (!(voxel_size >= 0.0)) err << "voxel_size must be >= 0 m, 0 disables it (got " << voxel_size << "); ";
  return err.str();
}

PointCloud voxelDownsample(const PointCloud& input, double leaf) {
  if (!(leaf > 0.0)) throw std::invalid_argument("voxelDownsample: leaf must be > 0 m");
  const double inv = 1.0 / leaf;
  struct Acc {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    std::size_t n = 0;
  };
  std::unordered_map<Eigen::Vector3i, std::size_t, VoxelKeyHash, VoxelKeyEqual> slot;
  slot.reserve(input.size());
  std::vector<Acc> acc;
  acc.reserve(input.size() / 4 + 1);
  for (const Point& p : input) {
    const Eigen::Vector3i key(static_cast<int>(std::floor(p.x() * inv)), static_cast<int>(std::floor(p.y() * inv)),
                              static_cast<int>(std::floor(p.z() * inv)));
    auto [it, inserted] = slot.try_emplace(key, acc.size());
    if (inserted) acc.emplace_back();
    Acc& a = acc[it->second];
    a.sum += p.cast<double>();
    ++a.n;
  }
  PointCloud out;
  out.reserve(acc.size());
  for (const Acc& a : acc) out.push_back((a.sum / static_cast<double>(a.n)).cast<float>());
  return out;
}

PointCloud preprocess(const PointCloud& input, const PreprocessConfig& config, PreprocessReport* report) {
  const std::string problem = config.validate();
  if (!problem.empty()) throw std::invalid_argument("preprocess: " + problem);
  PreprocessReport r;
  r.input = input.size();
  PointCloud kept;
  kept.reserve(input.size());
  const double min2 = config.min_range * config.min_range;
  const double max2 = config.max_range * config.max_range;
  for (const Point& p : input) {
    if (!p.allFinite()) {
      ++r.non_finite;
      continue;
    }
    if (p.x() == 0.0f && p.y() == 0.0f && p.z() == 0.0f) {
      ++r.at_origin;
      continue;
    }
    const double d2 = p.cast<double>().squaredNorm();
    if (d2 < min2 || d2 > max2) {
      ++r.out_of_range;
      continue;
    }
    kept.push_back(p);
  }
  PointCloud out = config.voxel_size > 0.0 ? voxelDownsample(kept, config.voxel_size) : std::move(kept);
  r.output = out.size();
  if (report) *report = r;
  return out;
}

}  // namespace grid_puzzle_localization
