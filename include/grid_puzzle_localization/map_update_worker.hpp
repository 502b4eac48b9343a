// Background preparation of the NDT target: map changes are queued from any thread, applied by one
// worker thread, and the resulting immutable snapshot is handed to the scan thread under a brief lock,
// so a map update never blocks scan matching. No ROS.
#pragma once

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#include "grid_puzzle_localization/map_extent.hpp"
#include "grid_puzzle_localization/map_store/map_store.hpp"
#include "grid_puzzle_localization/point_cloud.hpp"
#include "grid_puzzle_localization/tile_cache.hpp"
#include "grid_puzzle_localization/voxel_map.hpp"

namespace grid_puzzle_localization {

/// One tile of a tiles-mode change: its id (the tile file stem, e.g. "12_-4") and its points (map frame, m).
struct TileCloud {
  std::string id;
  PointCloud points;
};

/// Tiles by reference: which tile files of a directory enter and leave the window. The worker reads them.
struct TileFileChange {
  std::string dir;                    ///< tile directory: tile `id` is the file dir/id.pcd; or an http(s):// URL
                                      ///< of one (a map store: the worker fetches the tiles into its disk cache)
  std::string index_revision;         ///< identity of the directory's index; another value means other tiles
  bool reset = false;                 ///< drop every loaded tile (and the cache) before applying this change
  std::vector<std::string> added;     ///< tiles entering; an id already loaded is read again
  std::vector<std::string> removed;   ///< tiles leaving; unknown ids are ignored
  std::vector<std::string> prefetch;  ///< tiles likely to enter next: read into the cache while idle
  /// The provider's window after this change, tiles or none: where the window has no tile the map has no point.
  std::optional<MapExtent> window;
};

/// A change of the map, as the map sources produce it. Tiles are named by their file stem "cx_cy" (tile
/// centre in metres); with `grid_size` [m] a whole multiple of the NDT resolution the target is tile-aligned
/// (a leaving tile drops its voxels, nothing is kept per tile), otherwise each tile's statistics are kept so
/// that its removal subtracts them (more memory per voxel; MapUpdateStats::tile_aligned says which).
struct MapChange {
  enum class Kind { kFullCloud, kTiles, kTileFiles, kPcdFile };
  Kind kind = Kind::kFullCloud;
  PointCloud cloud;                  ///< kFullCloud: the whole map (map frame, m); replaces the target
  bool reset = false;                ///< kTiles: drop every loaded tile before applying this change
  double grid_size = 0.0;            ///< kTiles, kTileFiles: tile side s [m]
  std::vector<TileCloud> added;      ///< kTiles: tiles entering; an id already loaded is replaced
  std::vector<std::string> removed;  ///< kTiles: tiles leaving; unknown ids are ignored
  TileFileChange files;              ///< kTileFiles
  std::string pcd_path;              ///< kPcdFile: a PCD file read by the worker; replaces the target

  static MapChange fullCloud(PointCloud cloud);
  static MapChange tiles(bool reset, double grid_size, std::vector<TileCloud> added, std::vector<std::string> removed);
  static MapChange tileFiles(double grid_size, TileFileChange files);
  static MapChange pcdFile(std::string path);
};

/// Tile (i, j) of side `grid_size` named by the stem "cx_cy"; throws std::invalid_argument naming the stem.
TileKey tileKeyOfStem(const std::string& stem, double grid_size);

/// The tiles of a change still to load, handed out nearest first: each take() sorts what is left by the distance of
/// its tile's centre from the newest focus (the predicted position) along the farther axis (max |dx|, |dy|), so a pose
/// that moves on while a large change loads (a slow map store) still gets the tiles under its scans first, in growing
/// squares: the squares about the pose that the localizer waits for (map_wait_half_side) are whole as early as they can
/// be, not after the circle that reaches their corners. Without a focus, the change's own order (the
/// provider's: nearest the pose it served). Ids that are not tile names go last; loading them reports why.
class NearestFirstTiles {
 public:
  NearestFirstTiles(const std::vector<std::string>& ids, double grid_size);
  /// The next `count` ids (fewer at the end), nearest `focus` [m, map frame] first; ties keep their order.
  std::vector<std::string> take(std::size_t count, const std::optional<Eigen::Vector2d>& focus);
  /// Adds `ids` after those left (a change that joins while these load).
  void add(const std::vector<std::string>& ids);
  /// Drops those of `ids` still left (tiles that left the window before they were loaded).
  void remove(const std::vector<std::string>& ids);
  bool empty() const { return left_.empty(); }

 private:
  double grid_size_;
  struct Tile {
    std::string id;
    Eigen::Vector2d centre;  // [m]; NaN when the id is not a tile name
  };
  std::vector<Tile> left_;
};

/// Tiles of the provider's window that the map does not hold yet: named by the changes being applied and not yet
/// read (or fetched) and folded in. A tile whose read or fetch failed is not in flight: its error says why.
struct TilesInFlight {
  double tile_size = 0.0;  ///< [m]
  std::vector<TileKey> keys;
  /// How many of them meet the square of half side `half` [m] about `centre` (x y, map frame).
  std::size_t within(const Eigen::Vector2d& centre, double half) const;
};

/// A snapshot of the target with the tiles of the window it does not hold yet.
struct MapSnapshot {
  /// nullptr when only the tiles in flight changed (a change started loading): the map held stays.
  std::shared_ptr<const VoxelMap> map;
  TilesInFlight in_flight;
};

/// What the last finished update did.
struct MapUpdateStats {
  std::uint64_t generation = 0;  ///< snapshots of whole batches published so far
  /// Snapshots published while a change was still loading (a slow map store, a large window): the tiles nearest the
  /// pose arrive first and are matched on while the rest comes (every kPartialSnapshotPeriod at most).
  std::uint64_t partial_snapshots = 0;
  double update_ms = 0.0;     ///< wall time to apply the last batch of changes and snapshot [ms]
  std::size_t changes = 0;    ///< changes applied in the last batch
  std::size_t tiles = 0;      ///< tiles loaded (tiles mode)
  std::size_t voxels = 0;     ///< voxels with a valid Gaussian in the last snapshot
  std::size_t points = 0;     ///< points summed into the last snapshot
  std::size_t map_bytes = 0;  ///< heap bytes of the last snapshot's voxel storage (VoxelMap::bytes)
  bool tile_aligned = false;  ///< tiles mode: voxels are tile-aligned (see MapChange)
  // Tiles by reference, totals since start:
  std::size_t tiles_read = 0;        ///< tile files read (window and prefetch)
  std::size_t tile_points_read = 0;  ///< points in them
  double tile_read_ms = 0.0;         ///< wall time reading them [ms]
  double tile_fold_ms = 0.0;         ///< wall time folding window tiles into the target [ms]
  double tile_read_cpu_ms = 0.0;     ///< CPU time of the worker thread reading them [ms] (its share of a core)
  double tile_fold_cpu_ms = 0.0;     ///< CPU time of the worker thread folding them [ms]
  double worker_cpu_ms = 0.0;        ///< CPU time of the worker thread since it started [ms]: every change, snapshot,
                                     ///< read-ahead and heap trim (what keeping the map current costs a core)
  std::size_t cache_hits = 0;        ///< entering tiles served by the prefetch cache
  std::size_t cache_bytes = 0;       ///< bytes held by the prefetch cache now
  std::size_t points_outside = 0;    ///< tile-aligned: points not added because their voxel is in another tile
  // A tile directory given by URL (map store):
  bool map_store_reachable = true;    ///< the last request reached its server
  std::string map_store_error;        ///< its last failure, naming the URL; "" if none
  std::size_t map_store_fetched = 0;  ///< tiles downloaded (the rest came from its disk cache)
  std::uint64_t map_store_bytes = 0;  ///< tile bytes downloaded
  std::optional<MapExtent> window;    ///< the provider's window of the tiles loaded, when their change gave it
};

class MapUpdateWorker {
 public:
  /// Starts the worker thread. `params` must validate (throws std::invalid_argument otherwise); its
  /// `threads` is the OpenMP team of the updates, so a small value leaves cores to the scan thread.
  explicit MapUpdateWorker(const VoxelMapParams& params);
  static constexpr double kDefaultTileCacheMb = 1.0;
  /// The worker thread runs this much nicer than the thread that creates it (Linux: niceness is per thread), so on a
  /// loaded machine matching the scans comes first and the target updates take the time left over: a localizer that
  /// is busy with a large window change (a recovery) does not fall behind the scans because of it.
  static constexpr int kWorkerNiceIncrement = 10;
  /// Byte budget of the prefetch cache of tiles mode by reference [MiB] (>= 0; 0 = no prefetch). Thread-safe.
  void setTileCacheMb(double megabytes);
  /// Settings of the map store used for a tile directory given by URL (before the first such change). Thread-safe.
  void setMapStoreConfig(const MapStoreConfig& config);
  /// Stops the worker after the change in progress; queued changes are dropped.
  ~MapUpdateWorker();
  MapUpdateWorker(const MapUpdateWorker&) = delete;
  MapUpdateWorker& operator=(const MapUpdateWorker&) = delete;

  /// Where the vehicle is predicted to be [m, map frame]: tiles still to load go nearest it first (NearestFirstTiles).
  /// Thread-safe, returns at once; the localizer sets it with every scan.
  void setFocus(const Eigen::Vector2d& position);

  /// Queues `change`; returns at once. Thread-safe. Changes apply in submission order; everything queued
  /// while the worker is busy becomes one batch and one snapshot.
  void submit(MapChange change);

  /// The snapshot published since the last call, or nullptr. Thread-safe; the worker holds the lock only briefly. A
  /// caller keeps the previous snapshot until it gets one.
  std::shared_ptr<const VoxelMap> takeReady();
  /// takeReady() with the tiles of the window that snapshot does not hold yet. A change that starts loading announces
  /// its tiles at once, before any of them arrives (a snapshot without a map).
  std::optional<MapSnapshot> takeSnapshot();
  /// While a change loads, a snapshot of the tiles that have arrived is published at most this often [s].
  static constexpr double kPartialSnapshotPeriod = 0.25;

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
  // Applies one change; problems that leave the rest of the change usable (a bad tile) go to `failures`.
  void apply(NdtTarget& target, const MapChange& change, std::vector<std::string>& failures);
  void applyTileFiles(NdtTarget& target, double grid_size, const TileFileChange& change,
                      std::vector<std::string>& failures);
  // Tiles mode bookkeeping shared by both tile sources.
  void startTiles(NdtTarget& target, bool reset, double grid_size);
  void removeTiles(NdtTarget& target, const std::vector<std::string>& ids);
  // A tile on its way into the target: its voxels' statistics when tile-aligned (reduced as soon as it is read),
  // else its points.
  struct PendingTile {
    std::string id;
    TileVoxels voxels;
    PointCloud points;
  };
  // The tile `id` made from `points`; std::invalid_argument for an id that is not a tile name.
  PendingTile pendingTile(const std::string& id, PointCloud points) const;
  // Adds tiles as one target update when tile-aligned; a tile already loaded is replaced.
  void addTiles(NdtTarget& target, const std::vector<PendingTile>& batch);
  PointCloud readTile(const std::string& path);  // counts into stats_
  // The map store of `url` at `revision` (opened, or its index polled, as needed); throws std::invalid_argument
  // when it cannot be opened or the server's index is of another revision.
  MapStore& storeAt(const std::string& url, const std::string& revision);
  // The change names the directory (or URL) and index revision the held tiles came from.
  bool fromHeldSource(const TileFileChange& change) const;
  // A reset of the source, tile side and index revision the held tiles came from: they stay, only the rest is read.
  bool keepsHeldTiles(const TileFileChange& change, double grid_size) const;
  // The window tiles of `batch` not loaded yet (in_flight_), before it is applied.
  void planInFlight(const std::deque<MapChange>& batch);
  // Takes the changes queued next that can join a change of tile files from `change`'s directory and revision with
  // tiles of `grid_size` [m] while it loads (tile files of the same source, no reset), into joined_; returns them.
  std::deque<MapChange> takeJoining(double grid_size, const TileFileChange& change);
  void landed(const std::string& id);  // a tile left in_flight_: folded in, or failed
  TilesInFlight inFlight() const;      // in_flight_ as published
  void announceInFlight();             // publishes in_flight_ without a new map; mutex_ not held
  // Publishes the target with the tiles still in flight; `partial` while a change is loading. mutex_ not held.
  void publish(const NdtTarget& target, bool partial, double update_ms, std::size_t changes,
               std::vector<std::string>& failures);
  void readAhead();        // prefetch while nothing is queued
  void copyStoreStatus();  // the map store's status into stats_; mutex_ held
  std::optional<Eigen::Vector2d> focus() const;

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
  std::optional<MapSnapshot> ready_;  // the newest snapshot not yet taken
  // Owned by the worker thread only.
  VoxelMapParams params_;
  struct LoadedTile {
    TileKey key;
    TargetId id = 0;  // in the target when the voxels are not tile-aligned
  };
  std::unordered_map<std::string, LoadedTile> tiles_;
  double tile_size_ = 0.0;           // side of the loaded tiles [m]
  std::optional<MapExtent> window_;  // worker thread only: of the last tile change
  bool aligned_ = false;             // tile-aligned voxels for tile_size_
  TargetId next_id_ = 0;
  std::string tile_dir_, index_revision_;  // source of the loaded tiles (by reference)
  std::vector<std::string> prefetch_;      // ids still to read ahead
  TileCache cache_;                        // worker thread only; its budget comes from cache_budget_
  std::size_t cache_budget_;               // guarded by mutex_ (setTileCacheMb)
  MapStoreConfig store_config_;            // guarded by mutex_
  std::unique_ptr<MapStore> store_;        // worker thread only: the tile directory given by URL, if any
  std::vector<std::string> refetch_;       // worker thread only: window tiles its fetch failed, tried again
  bool prefetching_ = false;               // guarded by mutex_
  std::optional<Eigen::Vector2d> focus_;   // guarded by mutex_: the newest predicted position
  std::unordered_map<std::string, TileKey> in_flight_;  // worker thread only: window tiles not loaded yet, by id
  double in_flight_size_ = 0.0;                         // worker thread only: their tile side [m]
  std::deque<MapChange> joined_;                        // worker thread only: changes that joined the batch applied
  std::chrono::steady_clock::time_point published_;     // worker thread only: when the last snapshot went out
  MapUpdateStats totals_;                               // worker thread only: the by-reference totals of stats_
  std::thread worker_;
};

}  // namespace grid_puzzle_localization
