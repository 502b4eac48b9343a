#include "grid_puzzle_localization/voxel_map.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <unordered_set>

#include "omp_threads.hpp"
#include "packed_symmetric.hpp"

namespace grid_puzzle_localization {
namespace {

using Delta = std::vector<std::pair<VoxelKey, VoxelStats>>;

// Below these sizes a tile update runs on the calling thread: waking an OpenMP team costs more than the work (and
// on a loaded machine waiting for a descheduled team thread costs milliseconds).
constexpr std::size_t kMinParallelPoints = 20000;
constexpr std::size_t kMinParallelShards = 64;

std::size_t capacityFor(std::size_t n) {
  std::size_t cap = 4;
  while (cap < 2 * n) cap *= 2;
  return cap;
}

void rebuildSlots(VoxelMap::Shard& shard) {
  shard.slots.assign(capacityFor(shard.keys.size()), VoxelMap::Shard::Slot());
  const std::size_t mask = shard.slots.size() - 1;
  for (std::size_t i = 0; i < shard.keys.size(); ++i) {
    std::size_t s = VoxelMap::hash(shard.keys[i]) & mask;
    while (shard.slots[s].index >= 0) s = (s + 1) & mask;
    shard.slots[s] = {shard.keys[i], static_cast<std::int32_t>(i)};
  }
}

}  // namespace

std::string VoxelMapParams::validate() const {
  std::ostringstream err;
  if (!(resolution > 0.0 && std::isfinite(resolution))) err << "resolution must be > 0 m (got " << resolution << "); ";
  if (min_points_per_voxel < 3)
    err << "min_points_per_voxel must be >= 3 so a covariance exists (got " << min_points_per_voxel << "); ";
  if (!(eigenvalue_ratio > 0.0 && eigenvalue_ratio <= 1.0))
    err << "eigenvalue_ratio must be in (0, 1] (got " << eigenvalue_ratio << "); ";
  if (threads < 0) err << "threads must be >= 0, 0 = all cores (got " << threads << "); ";
  if (coarse_map_factor != 0 && (coarse_map_factor < 2 || coarse_map_factor > 8))
    err << "coarse_map_factor must be 0 (none) or in [2, 8] (got " << coarse_map_factor << "); ";
  return err.str();
}

void VoxelStats::add(const Eigen::Vector3d& l) {
  ++count;
  sum += l;
  for (int e = 0; e < 6; ++e) sum_sq[e] += l(packed_symmetric::kRow[e]) * l(packed_symmetric::kCol[e]);
}

void VoxelStats::merge(const VoxelStats& o) {
  count += o.count;
  sum += o.sum;
  for (int i = 0; i < 6; ++i) sum_sq[i] += o.sum_sq[i];
}

VoxelStats VoxelStats::shifted(const Eigen::Vector3d& d) const {
  // sum (l + d)(l + d)^T = sum l l^T + sum l d^T + d (sum l)^T + n d d^T, entry by packed entry
  VoxelStats out = *this;
  const double n = static_cast<double>(count);
  out.sum += n * d;
  for (int e = 0; e < 6; ++e) {
    const int i = packed_symmetric::kRow[e], j = packed_symmetric::kCol[e];
    out.sum_sq[e] += sum(i) * d(j) + d(i) * sum(j) + n * d(i) * d(j);
  }
  return out;
}

void VoxelStats::subtract(const VoxelStats& o) {
  count -= o.count;
  sum -= o.sum;
  for (int i = 0; i < 6; ++i) sum_sq[i] -= o.sum_sq[i];
}

namespace {
const VoxelMap::Shard::Slot kEmptySlot{};  // index -1: every probe of an empty shard ends here
}  // namespace

VoxelMap::VoxelMap(const VoxelMapParams& params) : params_(params), inv_resolution_(1.0 / params.resolution) {
  views_.fill({&kEmptySlot, nullptr, 0});
}

void VoxelMap::setShard(std::size_t index, std::shared_ptr<const Shard> shard) {
  views_[index] = shard ? ShardView{shard->slots.data(), shard->gaussians.data(), shard->slots.size() - 1}
                        : ShardView{&kEmptySlot, nullptr, 0};
  shards_[index] = std::move(shard);
}

VoxelKey VoxelMap::keyOf(const Eigen::Vector3f& p) const {
  const float inv = static_cast<float>(inv_resolution_);
  return {static_cast<std::int32_t>(std::floor(p.x() * inv)), static_cast<std::int32_t>(std::floor(p.y() * inv)),
          static_cast<std::int32_t>(std::floor(p.z() * inv))};
}

const VoxelStats* VoxelMap::stats(const VoxelKey& key) const {
  const std::uint64_t h = hash(key);
  const Shard* s = shards_[shardOf(key)].get();
  if (!s) return nullptr;
  const std::int32_t i = s->indexOf(key, h);
  return i >= 0 ? &s->stats[i] : nullptr;
}

std::size_t VoxelMap::bytes() const {
  std::size_t b = sizeof(shards_);
  for (const auto& s : shards_)
    if (s)
      b += sizeof(Shard) + s->slots.capacity() * sizeof(Shard::Slot) + s->keys.capacity() * sizeof(VoxelKey) +
           s->stats.capacity() * sizeof(VoxelStats) + s->gaussians.capacity() * sizeof(VoxelGaussian);
  return coarse_ ? b + sizeof(VoxelMap) + coarse_->bytes() : b;
}

double VoxelMap::bytesPerVoxel() const {
  return voxels_ ? static_cast<double>(bytes()) / static_cast<double>(voxels_) : 0.0;
}

VoxelGaussian deriveGaussian(const VoxelKey& key, const VoxelStats& st, const VoxelMapParams& params) {
  VoxelGaussian g;
  g.valid = 0;
  g.inv_cov.fill(0.0f);
  const Eigen::Vector3d corner(key.x * params.resolution, key.y * params.resolution, key.z * params.resolution);
  const double n = static_cast<double>(st.count);
  const Eigen::Vector3d mean_local = st.count > 0 ? Eigen::Vector3d(st.sum / n) : Eigen::Vector3d::Zero();
  g.mean = (corner + mean_local).cast<float>();
  if (st.count < params.min_points_per_voxel) return g;
  Eigen::Matrix3d sq;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) sq(i, j) = st.sum_sq[packed_symmetric::kIndex[i][j]];
  // Unbiased sample covariance: (sum x x^T - n mean mean^T) / (n - 1).
  const Eigen::Matrix3d cov = (sq - n * mean_local * mean_local.transpose()) / (n - 1.0);
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);
  if (eig.info() != Eigen::Success) return g;
  Eigen::Vector3d lambda = eig.eigenvalues();  // ascending
  const double largest = lambda(2);
  if (!(largest > 0.0) || !std::isfinite(largest)) return g;
  lambda = lambda.cwiseMax(params.eigenvalue_ratio * largest);
  const Eigen::Matrix3d icov = eig.eigenvectors() * lambda.cwiseInverse().asDiagonal() * eig.eigenvectors().transpose();
  if (!icov.allFinite()) return g;
  g.inv_cov = {static_cast<float>(icov(0, 0)), static_cast<float>(icov(0, 1)), static_cast<float>(icov(0, 2)),
               static_cast<float>(icov(1, 1)), static_cast<float>(icov(1, 2)), static_cast<float>(icov(2, 2))};
  g.valid = 1;
  return g;
}

std::vector<std::pair<VoxelKey, VoxelStats>> voxelStatistics(const PointCloud& points, double resolution, int threads) {
  const std::size_t n = points.size();
  const int nt = n < kMinParallelPoints ? 1 : resolveThreads(threads);
  const double inv = 1.0 / resolution;
  std::vector<VoxelKey> keys(n);
  std::vector<std::uint32_t> shard(n);
  std::vector<char> finite(n);
  // Per-thread shard histograms over a fixed static partition make the counting sort deterministic.
  std::vector<std::vector<std::size_t>> hist(nt, std::vector<std::size_t>(VoxelMap::kShards + 1, 0));
#pragma omp parallel num_threads(nt)
  {
    const int t = teamThreadNum();
    const std::size_t lo = n * t / nt, hi = n * (t + 1) / nt;
    for (std::size_t i = lo; i < hi; ++i) {
      const Eigen::Vector3d p = points[i].cast<double>();
      finite[i] = p.allFinite();
      if (!finite[i]) continue;
      keys[i] = {static_cast<std::int32_t>(std::floor(p.x() * inv)), static_cast<std::int32_t>(std::floor(p.y() * inv)),
                 static_cast<std::int32_t>(std::floor(p.z() * inv))};
      shard[i] = static_cast<std::uint32_t>(VoxelMap::shardOf(keys[i]));
      ++hist[t][shard[i] + 1];
    }
  }
  // start[s] = first position of shard s in the sorted order; cursor[t][s] = where thread t writes.
  std::vector<std::size_t> start(VoxelMap::kShards + 1, 0);
  std::vector<std::vector<std::size_t>> cursor(nt, std::vector<std::size_t>(VoxelMap::kShards, 0));
  std::size_t pos = 0;
  for (std::size_t s = 0; s < VoxelMap::kShards; ++s) {
    start[s] = pos;
    for (int t = 0; t < nt; ++t) {
      cursor[t][s] = pos;
      pos += hist[t][s + 1];
    }
  }
  start[VoxelMap::kShards] = pos;
  std::vector<std::uint32_t> order(pos);
#pragma omp parallel num_threads(nt)
  {
    const int t = teamThreadNum();
    const std::size_t lo = n * t / nt, hi = n * (t + 1) / nt;
    for (std::size_t i = lo; i < hi; ++i)
      if (finite[i]) order[cursor[t][shard[i]]++] = static_cast<std::uint32_t>(i);
  }
  // Each shard is grouped on its own, voxels in order of first appearance.
  std::vector<Delta> per_shard(VoxelMap::kShards);
#pragma omp parallel for num_threads(nt) schedule(dynamic, 16)
  for (std::size_t s = 0; s < VoxelMap::kShards; ++s) {
    if (start[s] == start[s + 1]) continue;
    VoxelMap::Shard table;
    Delta& out = per_shard[s];
    for (std::size_t o = start[s]; o < start[s + 1]; ++o) {
      const std::uint32_t i = order[o];
      const VoxelKey& k = keys[i];
      const std::uint64_t h = VoxelMap::hash(k);
      std::int32_t idx = table.indexOf(k, h);
      if (idx < 0) {
        idx = static_cast<std::int32_t>(out.size());
        out.push_back({k, VoxelStats()});
        table.keys.push_back(k);
        if (table.slots.size() < 2 * table.keys.size()) {
          rebuildSlots(table);
        } else {
          const std::size_t mask = table.slots.size() - 1;
          std::size_t sl = h & mask;
          while (table.slots[sl].index >= 0) sl = (sl + 1) & mask;
          table.slots[sl] = {k, idx};
        }
      }
      const Eigen::Vector3d corner(k.x * resolution, k.y * resolution, k.z * resolution);
      out[idx].second.add(points[i].cast<double>() - corner);
    }
  }
  Delta all;
  std::size_t total = 0;
  for (const auto& d : per_shard) total += d.size();
  all.reserve(total);
  for (auto& d : per_shard) all.insert(all.end(), d.begin(), d.end());
  return all;
}

NdtTarget::NdtTarget(const VoxelMapParams& params) : params_(params) {
  const std::string problem = params.validate();
  if (!problem.empty()) throw std::invalid_argument("NdtTarget: " + problem);
  current_ = std::make_shared<const VoxelMap>(params_);
  if (params_.coarse_map_factor > 0) {
    VoxelMapParams coarse = params_;
    coarse.resolution *= params_.coarse_map_factor;
    coarse.coarse_map_factor = 0;
    coarse_ = std::make_unique<NdtTarget>(coarse);
  }
}

NdtTarget::~NdtTarget() = default;

namespace {

std::int64_t floorDiv(std::int64_t a, std::int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }

struct KeyHash {
  std::size_t operator()(const VoxelKey& k) const { return static_cast<std::size_t>(VoxelMap::hash(k)); }
};

// The fine voxels' statistics `fine` (voxels of edge `resolution`) summed into voxels `factor` times as large, grouped
// by shard as apply() takes them: coarse voxel (i, j, k) holds the fine voxels (i * factor .. i * factor + factor - 1,
// ...), each shifted from its own corner to the coarse one's.
Delta coarseDelta(const Delta& fine, double resolution, int factor) {
  std::unordered_map<VoxelKey, std::size_t, KeyHash> index;
  Delta out;
  for (const auto& [k, st] : fine) {
    const VoxelKey c{static_cast<std::int32_t>(floorDiv(k.x, factor)), static_cast<std::int32_t>(floorDiv(k.y, factor)),
                     static_cast<std::int32_t>(floorDiv(k.z, factor))};
    const auto [it, added] = index.emplace(c, out.size());
    if (added) out.push_back({c, VoxelStats()});
    const Eigen::Vector3d offset =
        resolution * Eigen::Vector3d(k.x - c.x * factor, k.y - c.y * factor, k.z - c.z * factor);
    out[it->second].second.merge(st.shifted(offset));
  }
  std::stable_sort(out.begin(), out.end(), [](const auto& a, const auto& b) {
    return VoxelMap::shardOf(a.first) < VoxelMap::shardOf(b.first);
  });
  return out;
}

}  // namespace

void NdtTarget::applyCoarse(const Delta& delta, bool subtract, const VoxelMap& base) {
  if (!coarse_) return;
  // A map built on an empty base (setTarget) has no coarse map yet: its coarse map starts empty too.
  std::shared_ptr<const VoxelMap> coarse_base =
      base.coarse_ ? base.coarse_ : std::make_shared<const VoxelMap>(coarse_->params_);
  coarse_->apply(coarseDelta(delta, params_.resolution, params_.coarse_map_factor), subtract, std::move(coarse_base));
}

std::shared_ptr<const VoxelMap> NdtTarget::snapshot() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return current_;
}

void NdtTarget::publish(std::shared_ptr<VoxelMap> next) {
  if (coarse_) next->coarse_ = coarse_->snapshot();
  std::lock_guard<std::mutex> lock(mutex_);
  current_ = std::move(next);
}

void NdtTarget::setTarget(const PointCloud& points) {
  contributions_.clear();
  // Built on an empty base and published once: readers never see an empty map in between.
  const Delta delta = voxelStatistics(points, params_.resolution, params_.threads);
  apply(delta, false, std::make_shared<const VoxelMap>(params_));
}

void NdtTarget::addTarget(TargetId id, const PointCloud& points) {
  if (contributions_.count(id))
    throw std::invalid_argument("NdtTarget::addTarget: id " + std::to_string(id) +
                                " is already in the target; remove it before adding it again");
  Delta delta = voxelStatistics(points, params_.resolution, params_.threads);
  apply(delta, false, current_);
  contributions_.emplace(id, std::move(delta));
}

bool NdtTarget::removeTarget(TargetId id) {
  const auto it = contributions_.find(id);
  if (it == contributions_.end()) return false;
  apply(it->second, true, current_);
  contributions_.erase(it);
  return true;
}

int voxelsPerTileSide(double tile_size, double resolution) {
  if (!(tile_size > 0.0 && resolution > 0.0) || !std::isfinite(tile_size / resolution)) return 0;
  const double m = tile_size / resolution;
  const double whole = std::round(m);
  return whole >= 1.0 && whole < 1e6 && std::abs(m - whole) <= 1e-9 * m ? static_cast<int>(whole) : 0;
}

namespace {

// One int64 per tile for set lookups (exact for |i|, |j| < 2^31, like tiles/directory.py's codes).
std::int64_t tileCode(std::int64_t i, std::int64_t j) {
  return static_cast<std::int64_t>((static_cast<std::uint64_t>(i) << 32) |
                                   (static_cast<std::uint64_t>(j) & 0xFFFFFFFFu));
}

int checkedVoxelsPerTile(double tile_size, double resolution) {
  const int m = voxelsPerTileSide(tile_size, resolution);
  if (m == 0)
    throw std::invalid_argument("tile side " + std::to_string(tile_size) +
                                " m is not a whole multiple of the NDT resolution " + std::to_string(resolution) +
                                " m, so voxels would straddle tiles");
  return m;
}

}  // namespace

std::size_t NdtTarget::addTile(const TileKey& key, double tile_size, const PointCloud& points) {
  return addTiles({{key, &points}}, tile_size);
}

TileVoxels tileVoxels(const TileKey& key, double tile_size, double resolution, const PointCloud& points) {
  const std::int64_t m = checkedVoxelsPerTile(tile_size, resolution);
  const double inv = 1.0 / resolution;
  TileVoxels out;
  out.key = key;
  // The tile's own voxels: x in [x0, x0 + m), y in [y0, y0 + m) (voxel indices).
  const std::int64_t x0 = key.i * m, y0 = key.j * m;
  // Each voxel sums its points as they come, in the order of the cloud (a from-scratch build's order); then the few
  // voxels are put in key order. An open-addressing table from voxel to its entry: sorting the points by voxel costs
  // several times more.
  std::vector<std::int32_t> table(64, -1);  // entry index into out.voxels, -1 = empty; size a power of two
  const auto slotOf = [&table, &out](const VoxelKey& k) -> std::int32_t& {
    const std::size_t mask = table.size() - 1;
    for (std::size_t s = VoxelMap::hash(k) & mask;; s = (s + 1) & mask)
      if (table[s] < 0 || out.voxels[table[s]].first == k) return table[s];
  };
  std::int32_t last = -1;  // entry of the previous point (neighbouring points share voxels)
  for (const Eigen::Vector3f& point : points) {
    const Eigen::Vector3d p = point.cast<double>();
    if (!p.allFinite()) continue;
    // The voxel index voxelStatistics computes, so the owner test agrees with the voxel a point lands in.
    const VoxelKey k{static_cast<std::int32_t>(std::floor(p.x() * inv)),
                     static_cast<std::int32_t>(std::floor(p.y() * inv)),
                     static_cast<std::int32_t>(std::floor(p.z() * inv))};
    if (k.x < x0 || k.x >= x0 + m || k.y < y0 || k.y >= y0 + m) {
      ++out.outside;
      continue;
    }
    if (last < 0 || !(out.voxels[last].first == k)) {
      std::int32_t& slot = slotOf(k);
      if (slot >= 0) {
        last = slot;
      } else {
        last = slot = static_cast<std::int32_t>(out.voxels.size());
        out.voxels.emplace_back(k, VoxelStats());
        if (2 * out.voxels.size() > table.size()) {  // keep the load at most one half
          table.assign(2 * table.size(), -1);
          for (std::size_t e = 0; e < out.voxels.size(); ++e)
            slotOf(out.voxels[e].first) = static_cast<std::int32_t>(e);
        }
      }
    }
    out.voxels[last].second.add(p - Eigen::Vector3d(k.x * resolution, k.y * resolution, k.z * resolution));
  }
  std::sort(out.voxels.begin(), out.voxels.end(), [](const auto& a, const auto& b) {
    const VoxelKey &u = a.first, &v = b.first;
    if (u.x != v.x) return u.x < v.x;
    if (u.y != v.y) return u.y < v.y;
    return u.z < v.z;
  });
  out.voxels.shrink_to_fit();
  return out;
}

std::size_t NdtTarget::addTiles(const std::vector<std::pair<TileKey, const PointCloud*>>& tiles, double tile_size) {
  std::vector<TileVoxels> reduced;
  reduced.reserve(tiles.size());
  for (const auto& [key, points] : tiles) reduced.push_back(tileVoxels(key, tile_size, params_.resolution, *points));
  std::vector<const TileVoxels*> views;
  for (const TileVoxels& t : reduced) views.push_back(&t);
  return addTileVoxels(views);
}

std::size_t NdtTarget::addTileVoxels(const std::vector<const TileVoxels*>& tiles) {
  // apply() takes the voxels grouped by shard.
  std::vector<std::pair<std::uint32_t, const std::pair<VoxelKey, VoxelStats>*>> order;
  std::size_t outside = 0;
  for (const TileVoxels* t : tiles) {
    outside += t->outside;
    for (const auto& v : t->voxels) order.emplace_back(static_cast<std::uint32_t>(VoxelMap::shardOf(v.first)), &v);
  }
  std::stable_sort(order.begin(), order.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  Delta delta;
  delta.reserve(order.size());
  for (const auto& o : order) delta.push_back(*o.second);
  order = {};
  apply(delta, false, current_);
  return outside;
}

void NdtTarget::removeTiles(const std::vector<TileKey>& keys, double tile_size) {
  const std::int64_t m = checkedVoxelsPerTile(tile_size, params_.resolution);
  if (keys.empty()) return;
  std::unordered_set<std::int64_t> gone;
  for (const TileKey& k : keys) gone.insert(tileCode(k.i, k.j));
  const auto owned = [&](const VoxelKey& v) { return gone.count(tileCode(floorDiv(v.x, m), floorDiv(v.y, m))) != 0; };
  std::shared_ptr<const VoxelMap> base = current_;
  auto next = std::make_shared<VoxelMap>(*base);
  std::vector<std::int64_t> d_vox(VoxelMap::kShards, 0), d_gauss(VoxelMap::kShards, 0), d_pts(VoxelMap::kShards, 0);
  std::vector<Delta> removed(coarse_ ? VoxelMap::kShards : 0);  // what the coarse map loses, per shard
  const int nt = resolveThreads(params_.threads);
  // Every shard is scanned (a tile's voxels hash to all of them); only shards that lose a voxel are copied.
#pragma omp parallel for num_threads(nt) schedule(dynamic, 16)
  for (std::size_t s = 0; s < VoxelMap::kShards; ++s) {
    const VoxelMap::Shard* old = base->shards_[s].get();
    if (!old || std::none_of(old->keys.begin(), old->keys.end(), owned)) continue;
    auto shard = std::make_shared<VoxelMap::Shard>();
    const std::size_t kept = static_cast<std::size_t>(
        std::count_if(old->keys.begin(), old->keys.end(), [&](const VoxelKey& key) { return !owned(key); }));
    shard->keys.reserve(kept);  // exact sizes: a shard's vectors hold no growth slack
    shard->stats.reserve(kept);
    shard->gaussians.reserve(kept);
    for (std::size_t i = 0; i < old->keys.size(); ++i) {
      if (owned(old->keys[i])) {
        --d_vox[s];
        d_gauss[s] -= old->gaussians[i].valid;
        d_pts[s] -= old->stats[i].count;
        if (coarse_) removed[s].emplace_back(old->keys[i], old->stats[i]);
        continue;
      }
      shard->keys.push_back(old->keys[i]);
      shard->stats.push_back(old->stats[i]);
      shard->gaussians.push_back(old->gaussians[i]);
    }
    rebuildSlots(*shard);
    next->setShard(s, shard->keys.empty() ? nullptr : std::shared_ptr<const VoxelMap::Shard>(std::move(shard)));
  }
  for (std::size_t s = 0; s < VoxelMap::kShards; ++s) {
    next->voxels_ = static_cast<std::size_t>(static_cast<std::int64_t>(next->voxels_) + d_vox[s]);
    next->gaussians_ = static_cast<std::size_t>(static_cast<std::int64_t>(next->gaussians_) + d_gauss[s]);
    next->points_ = static_cast<std::size_t>(static_cast<std::int64_t>(next->points_) + d_pts[s]);
  }
  if (coarse_) {
    Delta gone_voxels;
    for (const Delta& d : removed) gone_voxels.insert(gone_voxels.end(), d.begin(), d.end());
    applyCoarse(gone_voxels, true, *base);
  }
  publish(std::move(next));
}

bool NdtTarget::hasTarget(TargetId id) const { return contributions_.count(id) != 0; }

std::vector<TargetId> NdtTarget::targetIds() const {
  std::vector<TargetId> ids;
  ids.reserve(contributions_.size());
  for (const auto& c : contributions_) ids.push_back(c.first);
  std::sort(ids.begin(), ids.end());
  return ids;
}

void NdtTarget::apply(const Delta& delta, bool subtract, std::shared_ptr<const VoxelMap> base) {
  auto next = std::make_shared<VoxelMap>(*base);  // shares every shard
  // delta is grouped by shard (voxelStatistics sorts it so): find each shard's range.
  std::vector<std::pair<std::size_t, std::size_t>> ranges;  // [begin, end) per touched shard
  for (std::size_t b = 0; b < delta.size();) {
    const std::size_t s = VoxelMap::shardOf(delta[b].first);
    std::size_t e = b + 1;
    while (e < delta.size() && VoxelMap::shardOf(delta[e].first) == s) ++e;
    ranges.emplace_back(b, e);
    b = e;
  }
  std::vector<std::int64_t> d_vox(ranges.size(), 0), d_gauss(ranges.size(), 0), d_pts(ranges.size(), 0);
  const int nt = ranges.size() < kMinParallelShards ? 1 : resolveThreads(params_.threads);
  bool missing = false;
#pragma omp parallel for num_threads(nt) schedule(dynamic, 4) reduction(|| : missing)
  for (std::size_t r = 0; r < ranges.size(); ++r) {
    const std::size_t s = VoxelMap::shardOf(delta[ranges[r].first].first);
    const VoxelMap::Shard* old = base->shards_[s].get();
    auto shard = std::make_shared<VoxelMap::Shard>();
    // Room for every voxel of the range up front (exact when they are all new, as for an added tile or a whole
    // map): growing by push_back would leave up to half of each vector as slack for as long as the shard lives.
    const std::size_t room = (old ? old->keys.size() : 0) + (subtract ? 0 : ranges[r].second - ranges[r].first);
    shard->keys.reserve(room);
    shard->stats.reserve(room);
    shard->gaussians.reserve(room);
    if (old) {
      shard->keys = old->keys;
      shard->stats = old->stats;
      shard->gaussians = old->gaussians;
      shard->slots = old->slots;
    }
    const std::int64_t vox_before = static_cast<std::int64_t>(shard->keys.size());
    std::int64_t gauss_before = 0;
    for (const auto& g : shard->gaussians) gauss_before += g.valid;
    std::vector<std::int32_t> touched;
    bool removed_any = false;
    for (std::size_t i = ranges[r].first; i < ranges[r].second; ++i) {
      const auto& [key, st] = delta[i];
      std::int32_t idx = shard->indexOf(key, VoxelMap::hash(key));
      if (idx < 0) {
        if (subtract) {  // cannot happen: an id's statistics were merged when it was added
          missing = true;
          continue;
        }
        idx = static_cast<std::int32_t>(shard->keys.size());
        shard->keys.push_back(key);
        shard->stats.emplace_back();
        shard->gaussians.emplace_back();
        if (shard->slots.size() < 2 * shard->keys.size()) {
          rebuildSlots(*shard);
        } else {
          const std::size_t mask = shard->slots.size() - 1;
          std::size_t sl = VoxelMap::hash(key) & mask;
          while (shard->slots[sl].index >= 0) sl = (sl + 1) & mask;
          shard->slots[sl] = {key, idx};
        }
      }
      VoxelStats& target = shard->stats[idx];
      if (subtract) {
        target.subtract(st);
        d_pts[r] -= st.count;
        removed_any |= target.count == 0;
      } else {
        target.merge(st);
        d_pts[r] += st.count;
      }
      touched.push_back(idx);
    }
    for (const std::int32_t idx : touched)
      shard->gaussians[idx] = deriveGaussian(shard->keys[idx], shard->stats[idx], params_);
    if (removed_any) {
      // Compact away emptied voxels; starting them from zero again drops any round-off residue.
      std::size_t w = 0;
      for (std::size_t i = 0; i < shard->keys.size(); ++i) {
        if (shard->stats[i].count == 0) continue;
        shard->keys[w] = shard->keys[i];
        shard->stats[w] = shard->stats[i];
        shard->gaussians[w] = shard->gaussians[i];
        ++w;
      }
      shard->keys.resize(w);
      shard->stats.resize(w);
      shard->gaussians.resize(w);
      rebuildSlots(*shard);
    }
    shard->keys.shrink_to_fit();  // no-ops when the reserve above was exact
    shard->stats.shrink_to_fit();
    shard->gaussians.shrink_to_fit();
    std::int64_t gauss_after = 0;
    for (const auto& g : shard->gaussians) gauss_after += g.valid;
    d_vox[r] = static_cast<std::int64_t>(shard->keys.size()) - vox_before;
    d_gauss[r] = gauss_after - gauss_before;
    next->setShard(s, shard->keys.empty() ? nullptr : std::shared_ptr<const VoxelMap::Shard>(std::move(shard)));
  }
  if (missing) throw std::logic_error("NdtTarget: removing statistics of a voxel that is not in the map");
  for (std::size_t r = 0; r < ranges.size(); ++r) {
    next->voxels_ = static_cast<std::size_t>(static_cast<std::int64_t>(next->voxels_) + d_vox[r]);
    next->gaussians_ = static_cast<std::size_t>(static_cast<std::int64_t>(next->gaussians_) + d_gauss[r]);
    next->points_ = static_cast<std::size_t>(static_cast<std::int64_t>(next->points_) + d_pts[r]);
  }
  applyCoarse(delta, subtract, *base);
  publish(std::move(next));
}

}  // namespace grid_puzzle_localization
