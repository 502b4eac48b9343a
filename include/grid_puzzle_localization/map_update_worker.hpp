// Background preparation of the NDT target: map changes are queued from any thread, applied by one
// worker thread, and the resulting immutable snapshot is handed to the scan thread with an atomic
// shared_ptr exchange, so a map update never blocks scan matching. No ROS.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "grid_puzzle_localization/point_cloud.hpp"
#include "grid_puzzle_localization/voxel_map.hpp"

namespace grid_puzzle_localization {

/// One tile of a tiles-mode change: its id (the tile file stem, e.g. "12_-4") and its points (map frame, m).
struct TileCloud {
  std::string id;
  PointCloud points;
};

/// A change of the map, as the three map sources produce it.
struct MapChange {
  enum class Kind { kFullCloud, kTiles, kPcdFile };
  Kind kind = Kind::kFullCloud;
  PointCloud cloud;                  ///< kFullCloud: the whole map (map frame, m); replaces the target
  bool reset = false;                ///< kTiles: drop every loaded tile before applying this change
  std::vector<TileCloud> added;      ///< kTiles: tiles entering; an id already loaded is replaced
  std::vector<std::string> removed;  ///< kTiles: tiles leaving; unknown ids are ignored
  std::string pcd_path;              ///< kPcdFile: a PCD file read by the worker; replaces the target

  static MapChange fullCloud(PointCloud cloud);
  static MapChange tiles(bool reset, std::vector<TileCloud> added, std::vector<std::string> removed);
  static MapChange pcdFile(std::string path);
};

/// What the last finished update did.
struct MapUpdateStats {
  std::uint64_t generation = 0;  ///< snapshots published so far
  double update_ms = 0.0;        ///< wall time to apply the last batch of changes and snapshot [ms]
  std::size_t changes = 0;       ///< changes applied in the last batch
  std::size_t tiles = 0;         ///< tiles loaded (tiles mode)
  std::size_t voxels = 0;        ///< voxels with a valid Gaussian in the last snapshot
  std::size_t points = 0;        ///< points summed into the last snapshot
};

class MapUpdateWorker {
 public:
  /// Starts the worker thread. `params` must validate (throws std::invalid_argument otherwise); its
  /// `threads` is the OpenMP team of the updates, so a small value leaves cores to the scan thread.
  explicit MapUpdateWorker(const VoxelMapParams& params);
  /// Stops the worker after the change in progress; queued changes are dropped.
  ~MapUpdateWorker();
  MapUpdateWorker(const MapUpdateWorker&) = delete;
  MapUpdateWorker& operator=(const MapUpdateWorker&) = delete;

  /// Queues `change`; returns at once. Thread-safe. Changes apply in submission order; everything queued
  /// while the worker is busy becomes one batch and one snapshot.
  void submit(MapChange change);

  /// The snapshot published since the last call, or nullptr. Thread-safe, wait-free for the caller in
  /// practice (an atomic shared_ptr exchange); a caller keeps the previous snapshot until it gets one.
  std::shared_ptr<const VoxelMap> takeReady();

  /// Hands a snapshot the caller is done with to the worker thread, which drops it there: freeing an old map
  /// (its voxel buffers) is background work, not the scan thread's. Thread-safe, returns at once.
  void retire(std::shared_ptr<const VoxelMap> snapshot);

  /// True while changes are queued or being applied. Thread-safe.
  bool busy() const;
  /// Blocks until no change is queued or in progress and every retired snapshot has been dropped (tests,
  /// benchmark, offline use).
  void waitIdle();
  MapUpdateStats stats() const;
  /// Errors of changes that failed (unreadable PCD file, ...) since the last call, oldest first.
  std::vector<std::string> takeErrors();

 private:
  void run();
  void apply(NdtTarget& target, const MapChange& change);

  mutable std::mutex mutex_;  // guards everything below up to worker_
  std::condition_variable wake_;
  std::condition_variable idle_;
  std::deque<MapChange> queue_;
  std::vector<std::shared_ptr<const VoxelMap>> retired_;
  bool working_ = false;    // a batch of changes is being applied
  bool releasing_ = false;  // retired snapshots are being dropped
  bool stop_ = false;
  MapUpdateStats stats_;
  std::vector<std::string> errors_;
  std::shared_ptr<const VoxelMap> ready_;  // accessed only with std::atomic_load/exchange/store
  // Owned by the worker thread only.
  VoxelMapParams params_;
  std::unordered_map<std::string, TargetId> tile_ids_;
  TargetId next_id_ = 0;
  std::thread worker_;
};

}  // namespace grid_puzzle_localization
