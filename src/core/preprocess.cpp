#include "grid_puzzle_localization/preprocess.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace grid_puzzle_localization {

std::string PreprocessConfig::validate() const {
  std::ostringstream err;
  if (!(min_range >= 0.0)) err << "min_range must be >= 0 m (got " << min_range << "); ";
  if (!(max_range > min_range)) err << "max_range must be > min_range (got " << max_range << " m); ";
  if (!(voxel_size >= 0.0)) err << "voxel_size must be >= 0 m, 0 disables it (got " << voxel_size << "); ";
  if (!(deskew_twist_smoothing >= 0.0))
    err << "deskew_twist_smoothing must be >= 0 s (got " << deskew_twist_smoothing << "); ";
  return err.str();
}

void VoxelCentroidFilter::apply(const PointCloud& input, double leaf, PointCloud& out) {
  if (!(leaf > 0.0)) throw std::invalid_argument("voxel filter: leaf must be > 0 m");
  std::size_t capacity = 16;
  while (capacity < 2 * input.size()) capacity *= 2;
  if (slots_.size() < capacity) slots_.assign(capacity, Slot{});
  const std::size_t mask = slots_.size() - 1;
  const double inv = 1.0 / leaf;
  sums_.clear();
  counts_.clear();
  used_slots_.clear();
  for (const Point& p : input) {
    // The key in double, as before: VoxelMap::keyOf multiplies in float and could pick a neighbouring voxel.
    const VoxelKey key{static_cast<std::int32_t>(std::floor(p.x() * inv)),
                       static_cast<std::int32_t>(std::floor(p.y() * inv)),
                       static_cast<std::int32_t>(std::floor(p.z() * inv))};
    std::size_t s = static_cast<std::size_t>(VoxelMap::hash(key)) & mask;
    while (slots_[s].voxel >= 0 && !(slots_[s].key == key)) s = (s + 1) & mask;
    if (slots_[s].voxel < 0) {
      slots_[s] = {key, static_cast<std::int32_t>(sums_.size())};
      used_slots_.push_back(s);
      sums_.push_back(Eigen::Vector3d::Zero());
      counts_.push_back(0);
    }
    sums_[slots_[s].voxel] += p.cast<double>();
    ++counts_[slots_[s].voxel];
  }
  for (std::size_t s : used_slots_) slots_[s].voxel = -1;  // empty again for the next call, in O(voxels)
  out.resize(sums_.size());
  for (std::size_t i = 0; i < sums_.size(); ++i) out[i] = (sums_[i] / static_cast<double>(counts_[i])).cast<float>();
}

Preprocessor::Preprocessor(const PreprocessConfig& config) : config_(config) {
  const std::string problem = config.validate();
  if (!problem.empty()) throw std::invalid_argument("preprocess: " + problem);
}

void Preprocessor::apply(const PointCloud& input, PointCloud& out, PreprocessReport* report, const PointTimes* times,
                         const SweepMotion* motion) {
  PreprocessReport r;
  r.input = input.size();
  const bool deskew = config_.deskew && times && motion;
  if (deskew && times->size() != input.size())
    throw std::invalid_argument("preprocess: " + std::to_string(times->size()) + " point times for " +
                                std::to_string(input.size()) + " points");
  PointCloud& kept = config_.voxel_size > 0.0 ? kept_ : out;
  kept.clear();
  kept_times_.clear();
  const double min2 = config_.min_range * config_.min_range;
  const double max2 = config_.max_range * config_.max_range;
  for (std::size_t i = 0; i < input.size(); ++i) {
    const Point& p = input[i];
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
    if (deskew) kept_times_.push_back((*times)[i]);
  }
  if (deskew) motion->apply(kept, kept_times_);
  r.deskewed = deskew;
  if (config_.voxel_size > 0.0) voxel_filter_.apply(kept, config_.voxel_size, out);
  r.output = out.size();
  if (report) *report = r;
}

PointCloud preprocess(const PointCloud& input, const PreprocessConfig& config, PreprocessReport* report) {
  PointCloud out;
  Preprocessor(config).apply(input, out, report);
  return out;
}

PointCloud voxelDownsample(const PointCloud& input, double leaf) {
  PointCloud out;
  VoxelCentroidFilter().apply(input, leaf, out);
  return out;
}

}  // namespace grid_puzzle_localization
