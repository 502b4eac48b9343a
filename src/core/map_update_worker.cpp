#include "grid_puzzle_localization/map_update_worker.hpp"

#include <chrono>
#include <stdexcept>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "grid_puzzle_localization/pcd_reader.hpp"

namespace grid_puzzle_localization {

MapChange MapChange::fullCloud(PointCloud cloud) {
  MapChange c;
  c.kind = Kind::kFullCloud;
  c.cloud = std::move(cloud);
  return c;
}

MapChange MapChange::tiles(bool reset, std::vector<TileCloud> added, std::vector<std::string> removed) {
  MapChange c;
  c.kind = Kind::kTiles;
  c.reset = reset;
  c.added = std::move(added);
  c.removed = std::move(removed);
  return c;
}

MapChange MapChange::pcdFile(std::string path) {
  MapChange c;
  c.kind = Kind::kPcdFile;
  c.pcd_path = std::move(path);
  return c;
}

MapUpdateWorker::MapUpdateWorker(const VoxelMapParams& params) : params_(params) {
  const std::string problem = params.validate();
  if (!problem.empty()) throw std::invalid_argument("MapUpdateWorker: " + problem);
  worker_ = std::thread(&MapUpdateWorker::run, this);
}

MapUpdateWorker::~MapUpdateWorker() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  worker_.join();
}

void MapUpdateWorker::submit(MapChange change) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    queue_.push_back(std::move(change));
  }
  wake_.notify_one();
}

std::shared_ptr<const VoxelMap> MapUpdateWorker::takeReady() {
  return std::atomic_exchange(&ready_, std::shared_ptr<const VoxelMap>());
}

void MapUpdateWorker::retire(std::shared_ptr<const VoxelMap> snapshot) {
  if (!snapshot) return;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    retired_.push_back(std::move(snapshot));
  }
  wake_.notify_one();
}

bool MapUpdateWorker::busy() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return working_ || !queue_.empty();
}

void MapUpdateWorker::waitIdle() {
  std::unique_lock<std::mutex> lock(mutex_);
  idle_.wait(lock, [this] { return !working_ && !releasing_ && queue_.empty() && retired_.empty(); });
}

MapUpdateStats MapUpdateWorker::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

std::vector<std::string> MapUpdateWorker::takeErrors() {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<std::string> out;
  out.swap(errors_);
  return out;
}

void MapUpdateWorker::apply(NdtTarget& target, const MapChange& change) {
  switch (change.kind) {
    case MapChange::Kind::kFullCloud:
      target.setTarget(change.cloud);
      tile_ids_.clear();
      break;
    case MapChange::Kind::kPcdFile:
      target.setTarget(readPcdXyz(change.pcd_path));
      tile_ids_.clear();
      break;
    case MapChange::Kind::kTiles:
      if (change.reset) {
        target.setTarget(PointCloud());
        tile_ids_.clear();
      }
      for (const std::string& id : change.removed) {
        const auto it = tile_ids_.find(id);
        if (it == tile_ids_.end()) continue;
        target.removeTarget(it->second);
        tile_ids_.erase(it);
      }
      for (const TileCloud& tile : change.added) {
        const auto it = tile_ids_.find(tile.id);
        if (it != tile_ids_.end()) {
          target.removeTarget(it->second);
          tile_ids_.erase(it);
        }
        target.addTarget(next_id_, tile.points);
        tile_ids_.emplace(tile.id, next_id_++);
      }
      break;
  }
}

namespace {

// glibc keeps freed heap pages in its per-thread arenas. Map updates free whole tile clouds and map
// shards from several threads (callback, worker, OpenMP team), so without a trim the process keeps
// the high-water mark of every arena and its RSS creeps up as the window moves.
void returnFreedMemory() {
#if defined(__GLIBC__)
  malloc_trim(0);
#endif
}

}  // namespace

void MapUpdateWorker::run() {
  NdtTarget target(params_);
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    wake_.wait(lock, [this] { return stop_ || !queue_.empty() || !retired_.empty(); });
    if (stop_) return;
    std::deque<MapChange> batch;
    batch.swap(queue_);
    std::vector<std::shared_ptr<const VoxelMap>> retired;
    retired.swap(retired_);
    working_ = !batch.empty();
    releasing_ = !retired.empty();
    lock.unlock();

    // Old snapshots the scan thread handed back are freed here (when no other holder is left).
    retired.clear();
    std::shared_ptr<const VoxelMap> snapshot;
    std::vector<std::string> failures;
    double ms = 0.0;
    if (!batch.empty()) {
      const auto start = std::chrono::steady_clock::now();
      for (const MapChange& change : batch) {
        try {
          apply(target, change);
        } catch (const std::exception& e) {
          failures.emplace_back(e.what());
        }
      }
      snapshot = target.snapshot();
      ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
      std::atomic_store(&ready_, snapshot);
    }

    lock.lock();
    if (snapshot) {
      ++stats_.generation;
      stats_.update_ms = ms;
      stats_.changes = batch.size();
      stats_.tiles = tile_ids_.size();
      stats_.voxels = snapshot->gaussianCount();
      stats_.points = snapshot->pointCount();
      errors_.insert(errors_.end(), failures.begin(), failures.end());
    }
    working_ = false;
    releasing_ = false;
    // Freeing the applied batch (large clouds) is the worker's job, not the scan thread's.
    lock.unlock();
    batch.clear();
    returnFreedMemory();
    lock.lock();
    if (queue_.empty() && retired_.empty()) idle_.notify_all();
  }
}

}  // namespace grid_puzzle_localization
