// NDT target: world-aligned voxels with exact sufficient statistics, as immutable snapshots that an
// incremental builder (NdtTarget) publishes. No ROS includes here.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "grid_puzzle_localization/point_cloud.hpp"
#include "grid_puzzle_localization/tile_geometry.hpp"  // TileKey

namespace grid_puzzle_localization {

/// Parameters of the voxel Gaussians (NdtConfig derives from this struct; a snapshot keeps a copy).
struct VoxelMapParams {
  double resolution = 1.0;         ///< [m] voxel edge; voxel (i, j, k) covers [i, i+1) * resolution etc.
  int min_points_per_voxel = 6;    ///< voxels with fewer points get no Gaussian (>= 3 so a covariance exists)
  double eigenvalue_ratio = 0.01;  ///< smaller covariance eigenvalues are raised to ratio * largest, in (0, 1]
  int threads = 0;                 ///< OpenMP threads for builds and updates; 0 = all cores
  /// 0 or in [2, 8]: each snapshot also holds its points in voxels this many times as large (VoxelMap::coarse), where
  /// NdtAligner's coarse stage starts: a guess metres off lies within reach of those voxels. 0 = none.
  int coarse_map_factor = 3;

  /// Empty when usable, else a message naming the bad value and its allowed range.
  std::string validate() const;
};

/// Integer voxel coordinates: floor(coordinate / resolution) on each axis.
struct VoxelKey {
  std::int32_t x = 0, y = 0, z = 0;
  bool operator==(const VoxelKey& o) const { return x == o.x && y == o.y && z == o.z; }
};

/// Sufficient statistics of the points in one voxel, in double and relative to the voxel's own corner
/// (key * resolution) so that large map coordinates do not cancel. Adding and subtracting them is exact up to
/// double round-off, which is what makes add/remove of tiles equal a from-scratch build.
struct VoxelStats {
  std::int64_t count = 0;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();  ///< [m] sum of (p - corner)
  std::array<double, 6> sum_sq{};                 ///< [m^2] xx xy xz yy yz zz of sum (p - corner)(p - corner)^T

  void add(const Eigen::Vector3d& local);
  void merge(const VoxelStats& o);     ///< this += o
  void subtract(const VoxelStats& o);  ///< this -= o (o must be a part previously merged)
  /// The same points relative to a corner `offset` [m] lower: local + offset for every point.
  VoxelStats shifted(const Eigen::Vector3d& offset) const;
};

/// Derived Gaussian of one voxel, compact and in float for the alignment inner loop (40 bytes).
struct VoxelGaussian {
  Eigen::Vector3f mean;          ///< [m] world frame
  std::array<float, 6> inv_cov;  ///< [1/m^2] xx xy xz yy yz zz of the regularised inverse covariance
  std::int32_t valid;            ///< 1 when the voxel has enough points and a usable covariance, else 0
};

/// An immutable voxel map snapshot. Thread-safety: every const method may be called from any number of
/// threads at once; nothing mutates a published snapshot (NdtTarget copies the shards it changes). Hold the
/// shared_ptr for as long as you read from it.
class VoxelMap {
 public:
  /// Number of shards; fixed so a shard index never changes under incremental updates.
  static constexpr int kShardBits = 10;
  /// Voxels of one block of 2^kBlockBits voxels a side share a shard (blocks are hashed to shards): a change of a
  /// small area (tiles entering or leaving a window) copies the few shards of its blocks, not every shard.
  static constexpr int kBlockBits = 3;
  static constexpr std::size_t kShards = std::size_t{1} << kShardBits;

  /// One shard: an open-addressing table of keys plus dense per-voxel arrays.
  struct Shard {
    struct Slot {
      VoxelKey key;
      std::int32_t index = -1;  ///< into stats/gaussians; -1 = empty slot
    };
    std::vector<Slot> slots;  ///< capacity is a power of two, load <= 0.5
    std::vector<VoxelKey> keys;
    std::vector<VoxelStats> stats;
    std::vector<VoxelGaussian> gaussians;

    /// Index of `key` (whose VoxelMap::hash is `hash`) into keys/stats/gaussians, or -1.
    std::int32_t indexOf(const VoxelKey& key, std::uint64_t hash) const {
      if (slots.empty()) return -1;
      const std::size_t mask = slots.size() - 1;
      for (std::size_t s = hash & mask;; s = (s + 1) & mask) {
        if (slots[s].index < 0) return -1;
        if (slots[s].key == key) return slots[s].index;
      }
    }
  };

  explicit VoxelMap(const VoxelMapParams& params);

  const VoxelMapParams& params() const { return params_; }
  double resolution() const { return params_.resolution; }
  VoxelKey keyOf(const Eigen::Vector3f& p) const;

  /// The Gaussian of voxel `key` if it exists and is valid, else nullptr. The pointer lives as long as this map.
  const VoxelGaussian* find(const VoxelKey& key) const {
    const std::uint64_t h = hash(key);
    const ShardView& v = views_[shardOf(key)];
    for (std::size_t s = h & v.mask;; s = (s + 1) & v.mask) {
      const Shard::Slot& slot = v.slots[s];
      if (slot.index < 0) return nullptr;
      if (slot.key == key) return v.gaussians[slot.index].valid ? &v.gaussians[slot.index] : nullptr;
    }
  }
  /// Statistics of voxel `key` (nullptr when no point fell into it).
  const VoxelStats* stats(const VoxelKey& key) const;

  std::size_t voxelCount() const { return voxels_; }        ///< voxels holding at least one point
  std::size_t gaussianCount() const { return gaussians_; }  ///< voxels with a valid Gaussian
  std::size_t pointCount() const { return points_; }        ///< points summed into the map
  std::size_t bytes() const;                                ///< heap bytes of the voxel storage and the coarse map
  double bytesPerVoxel() const;                             ///< bytes() / voxelCount()
  /// The same points in voxels params().coarse_map_factor times as large (a map without a coarse map of its own), or
  /// nullptr (coarse_map_factor 0, or the empty map an NdtTarget starts with). Lives as long as this map.
  const VoxelMap* coarse() const { return coarse_.get(); }
  /// Calls f(key, stats, gaussian) for every voxel, in an unspecified but deterministic order.
  template <class F>
  void forEach(F&& f) const {
    for (const auto& s : shards_)
      if (s)
        for (std::size_t i = 0; i < s->keys.size(); ++i) f(s->keys[i], s->stats[i], s->gaussians[i]);
  }

  static std::uint64_t hash(const VoxelKey& k) {
    // Pack, then the splitmix64 finaliser: shard (top bits) and slot (low bits) both get well-mixed bits.
    std::uint64_t h = (static_cast<std::uint64_t>(static_cast<std::uint32_t>(k.x)) * 0x9E3779B97F4A7C15ULL) ^
                      (static_cast<std::uint64_t>(static_cast<std::uint32_t>(k.y)) * 0xC2B2AE3D27D4EB4FULL) ^
                      (static_cast<std::uint64_t>(static_cast<std::uint32_t>(k.z)) * 0x165667B19E3779F9ULL);
    h ^= h >> 30;
    h *= 0xBF58476D1CE4E5B9ULL;
    h ^= h >> 27;
    h *= 0x94D049BB133111EBULL;
    return h ^ (h >> 31);
  }
  /// The shard of voxel `key`: a multiplicative hash of its block (arithmetic shifts floor negative indices).
  static std::size_t shardOf(const VoxelKey& k) {
    const std::uint64_t h =
        (static_cast<std::uint64_t>(static_cast<std::uint32_t>(k.x >> kBlockBits)) * 0x9E3779B97F4A7C15ULL) ^
        (static_cast<std::uint64_t>(static_cast<std::uint32_t>(k.y >> kBlockBits)) * 0xC2B2AE3D27D4EB4FULL) ^
        (static_cast<std::uint64_t>(static_cast<std::uint32_t>(k.z >> kBlockBits)) * 0x165667B19E3779F9ULL);
    return static_cast<std::size_t>((h ^ (h >> 29)) * 0xBF58476D1CE4E5B9ULL >> (64 - kShardBits));
  }

 private:
  friend class NdtTarget;
  VoxelMapParams params_;
  double inv_resolution_;
  // Raw views of the shards for the lookup hot path (one dependent load less); an empty shard views kEmptySlot.
  struct ShardView {
    const Shard::Slot* slots;
    const VoxelGaussian* gaussians;
    std::size_t mask;
  };
  void setShard(std::size_t index, std::shared_ptr<const Shard> shard);

  std::array<std::shared_ptr<const Shard>, kShards> shards_{};  ///< nullptr = empty shard
  std::array<ShardView, kShards> views_;
  std::size_t voxels_ = 0, gaussians_ = 0, points_ = 0;
  std::shared_ptr<const VoxelMap> coarse_;
};

/// Identifier of a cloud added with NdtTarget::addTarget (for example a tile index).
using TargetId = std::uint64_t;

/// Voxels along a tile side when `tile_size` is a whole multiple of `resolution` (to 1e-9 relative), else 0.
/// Only then does every voxel lie in exactly one tile (tile-aligned voxels).
int voxelsPerTileSide(double tile_size, double resolution);

/// One tile reduced to the statistics of its own voxels (tile-aligned voxels): what NdtTarget::addTileVoxels
/// folds in, and what the prefetch cache keeps of a tile read ahead (a few dozen times smaller than its points).
struct TileVoxels {
  TileKey key;
  std::vector<std::pair<VoxelKey, VoxelStats>> voxels;  ///< one entry per voxel, in ascending key order
  std::size_t outside = 0;  ///< finite points dropped because their voxel lies in another tile
  std::size_t bytes() const { return sizeof(TileVoxels) + voxels.capacity() * sizeof(voxels.front()); }
};

/// Reduces the points of tile `key` of side `tile_size` [m] to its voxels' statistics. `tile_size` must be a whole
/// multiple of `resolution` (voxelsPerTileSide > 0; else std::invalid_argument). Each voxel sums its points in the
/// order of `points`, as a from-scratch build of the same points does, so the statistics are exactly equal.
TileVoxels tileVoxels(const TileKey& key, double tile_size, double resolution, const PointCloud& points);

/// Builds and incrementally updates the NDT target, publishing immutable VoxelMap snapshots.
///
/// Ownership and threads: an NdtTarget is a single-writer object. Call its mutating methods (setTarget,
/// addTarget, removeTarget) from one thread at a time, e.g. a background map thread; they are internally
/// parallel (OpenMP, `threads` of the config). Each mutation builds a new snapshot that shares every
/// unchanged shard with the previous one and copies only the shards holding touched voxels, then publishes
/// it. snapshot() may be called from any thread at any time (it is guarded by a mutex) and returns a
/// shared_ptr<const VoxelMap>; a foreground align() against it never races with an ongoing update, and the
/// snapshot stays valid (and unchanged) for as long as the caller holds it.
class NdtTarget {
 public:
  /// Throws std::invalid_argument when params.validate() is not empty.
  explicit NdtTarget(const VoxelMapParams& params);
  ~NdtTarget();

  /// Replaces the whole target by `points` (world frame, metres). Forgets every added id.
  void setTarget(const PointCloud& points);
  /// Adds `points` under `id`; only voxels those points touch change. Throws std::invalid_argument if `id`
  /// is already present (remove it first). A voxel straddling two clouds holds the sum of both.
  void addTarget(TargetId id, const PointCloud& points);
  /// Removes the cloud added under `id` exactly (its statistics are subtracted). Returns false if absent.
  bool removeTarget(TargetId id);
  bool hasTarget(TargetId id) const;

  /// Tile-aligned update: adds the points of tile `key` of side `tile_size` [m], which must be a whole
  /// multiple of the resolution (voxelsPerTileSide > 0; else std::invalid_argument). Every voxel then lies in
  /// exactly one tile, so nothing is kept per tile: removeTiles drops the tile's voxels. Points whose voxel lies
  /// outside the tile (a point on the wrong side of a border) are not added; returns their number. The tile
  /// must not be in the target (remove it first).
  std::size_t addTile(const TileKey& key, double tile_size, const PointCloud& points);
  /// addTile of several tiles (distinct keys) as one update: each touched shard is copied once, not once per tile.
  std::size_t addTiles(const std::vector<std::pair<TileKey, const PointCloud*>>& tiles, double tile_size);
  /// Adds tiles already reduced by tileVoxels (distinct keys, none in the target, the same resolution) as one
  /// update. Returns the points they dropped as outside.
  std::size_t addTileVoxels(const std::vector<const TileVoxels*>& tiles);
  /// Drops every voxel of the tiles `keys` (side `tile_size`, as in addTile).
  void removeTiles(const std::vector<TileKey>& keys, double tile_size);
  std::vector<TargetId> targetIds() const;  ///< ids currently added, ascending

  /// The current snapshot (never null; empty before the first set/add). Thread-safe.
  std::shared_ptr<const VoxelMap> snapshot() const;

 private:
  // Publishes `base` changed by `delta`. Only the writer replaces current_, so it may read it without the lock.
  void apply(const std::vector<std::pair<VoxelKey, VoxelStats>>& delta, bool subtract,
             std::shared_ptr<const VoxelMap> base);
  // Applies the change of the fine voxels `delta` to the coarse map, whose state before it is `base`'s.
  void applyCoarse(const std::vector<std::pair<VoxelKey, VoxelStats>>& delta, bool subtract, const VoxelMap& base);
  // Gives `next` the coarse map's snapshot and makes it the snapshot.
  void publish(std::shared_ptr<VoxelMap> next);

  VoxelMapParams params_;
  std::shared_ptr<const VoxelMap> current_;  // guarded by mutex_ for readers; written only by the writer
  // The per-voxel statistics each id added, kept so that removal is exact.
  std::unordered_map<TargetId, std::vector<std::pair<VoxelKey, VoxelStats>>> contributions_;
  mutable std::mutex mutex_;  // guards current_ between the writer and snapshot() readers
  // The coarse map (VoxelMapParams::coarse_map_factor; none at 0), changed by the coarse sums of each fine change.
  std::unique_ptr<NdtTarget> coarse_;
};

/// Groups `points` into per-voxel statistics (parallel, deterministic order). Exposed for tests/benchmarks.
std::vector<std::pair<VoxelKey, VoxelStats>> voxelStatistics(const PointCloud& points, double resolution, int threads);

/// Derives the regularised Gaussian of a voxel from its statistics (unbiased n-1 covariance).
VoxelGaussian deriveGaussian(const VoxelKey& key, const VoxelStats& stats, const VoxelMapParams& params);

}  // namespace grid_puzzle_localization
