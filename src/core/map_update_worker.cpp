#include "grid_puzzle_localization/map_update_worker.hpp"

#include <sys/stat.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <stdexcept>
#include <unordered_set>
#include <utility>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include "grid_puzzle_localization/pcd_reader.hpp"
#include "grid_puzzle_localization/tile_geometry.hpp"
#include "thread_priority.hpp"

namespace grid_puzzle_localization {

MapChange MapChange::fullCloud(PointCloud cloud) {
  MapChange c;
  c.kind = Kind::kFullCloud;
  c.cloud = std::move(cloud);
  return c;
}

MapChange MapChange::tiles(bool reset, double grid_size, std::vector<TileCloud> added,
                           std::vector<std::string> removed) {
  MapChange c;
  c.kind = Kind::kTiles;
  c.reset = reset;
  c.grid_size = grid_size;
  c.added = std::move(added);
  c.removed = std::move(removed);
  return c;
}

MapChange MapChange::tileFiles(double grid_size, TileFileChange files) {
  MapChange c;
  c.kind = Kind::kTileFiles;
  c.grid_size = grid_size;
  c.files = std::move(files);
  return c;
}

TileKey tileKeyOfStem(const std::string& stem, double grid_size) {
  const std::size_t sep = stem.find('_');
  const char* begin = stem.c_str();
  char* end = nullptr;
  const double cx = std::strtod(begin, &end);
  const bool x_ok = sep != std::string::npos && end == begin + sep;
  const double cy = x_ok ? std::strtod(begin + sep + 1, &end) : 0.0;
  if (!x_ok || end != begin + stem.size() || sep + 1 == stem.size() || !std::isfinite(cx) || !std::isfinite(cy) ||
      !(grid_size > 0.0))
    throw std::invalid_argument("tile id '" + stem +
                                "' is not a tile name <cx>_<cy> (centre in metres, e.g. 1.0_-3.0)");
  // The centre is mid-tile, so floor is far from a rounding edge.
  return {static_cast<std::int64_t>(std::floor(cx / grid_size)), static_cast<std::int64_t>(std::floor(cy / grid_size))};
}

NearestFirstTiles::NearestFirstTiles(const std::vector<std::string>& ids, double grid_size) : grid_size_(grid_size) {
  add(ids);
}

void NearestFirstTiles::add(const std::vector<std::string>& ids) {
  left_.reserve(left_.size() + ids.size());
  for (const std::string& id : ids) {
    Eigen::Vector2d centre = Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
    try {
      const TileKey key = tileKeyOfStem(id, grid_size_);
      centre = tileCentre(key, grid_size_);
    } catch (const std::invalid_argument&) {
      // Reported when the tile is loaded.
    }
    left_.push_back({id, centre});
  }
}

void NearestFirstTiles::remove(const std::vector<std::string>& ids) {
  const std::unordered_set<std::string> leaving(ids.begin(), ids.end());
  left_.erase(std::remove_if(left_.begin(), left_.end(), [&](const Tile& t) { return leaving.count(t.id) > 0; }),
              left_.end());
}

std::vector<std::string> NearestFirstTiles::take(std::size_t count, const std::optional<Eigen::Vector2d>& focus) {
  if (focus) {
    const auto distance = [&](const Tile& t) {
      return t.centre.allFinite() ? (t.centre - *focus).cwiseAbs().maxCoeff() : std::numeric_limits<double>::infinity();
    };
    std::stable_sort(left_.begin(), left_.end(),
                     [&](const Tile& a, const Tile& b) { return distance(a) < distance(b); });
  }
  const std::size_t n = std::min(count, left_.size());
  std::vector<std::string> out;
  out.reserve(n);
  for (std::size_t k = 0; k < n; ++k) out.push_back(std::move(left_[k].id));
  left_.erase(left_.begin(), left_.begin() + static_cast<std::ptrdiff_t>(n));
  return out;
}

std::size_t TilesInFlight::within(const Eigen::Vector2d& centre, double half) const {
  std::size_t n = 0;
  for (const TileKey& key : keys) {
    const Eigen::Vector2d low = tileLow(key, tile_size);
    const Eigen::Vector2d far = (low.array() + tile_size).matrix();
    if ((low.array() < centre.array() + half).all() && (far.array() > centre.array() - half).all()) ++n;
  }
  return n;
}

MapChange MapChange::pcdFile(std::string path) {
  MapChange c;
  c.kind = Kind::kPcdFile;
  c.pcd_path = std::move(path);
  return c;
}

MapUpdateWorker::MapUpdateWorker(const VoxelMapParams& params)
    : params_(params), cache_budget_(static_cast<std::size_t>(kDefaultTileCacheMb * 1024 * 1024)) {
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

void MapUpdateWorker::setTileCacheMb(double megabytes) {
  if (!(megabytes >= 0.0))
    throw std::invalid_argument("tile cache budget must be >= 0 MiB (got " + std::to_string(megabytes) + ")");
  std::lock_guard<std::mutex> lock(mutex_);
  cache_budget_ = static_cast<std::size_t>(megabytes * 1024 * 1024);
}

void MapUpdateWorker::setMapStoreConfig(const MapStoreConfig& config) {
  const std::string problem = config.validate();
  if (!problem.empty()) throw std::invalid_argument(problem);
  std::lock_guard<std::mutex> lock(mutex_);
  store_config_ = config;
}

void MapUpdateWorker::setFocus(const Eigen::Vector2d& position) {
  std::lock_guard<std::mutex> lock(mutex_);
  focus_ = position;
}

std::optional<Eigen::Vector2d> MapUpdateWorker::focus() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return focus_;
}

void MapUpdateWorker::submit(MapChange change) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    queue_.push_back(std::move(change));
  }
  wake_.notify_one();
}

std::optional<MapSnapshot> MapUpdateWorker::takeSnapshot() {
  std::lock_guard<std::mutex> lock(mutex_);
  return std::exchange(ready_, std::nullopt);
}

std::shared_ptr<const VoxelMap> MapUpdateWorker::takeReady() {
  std::optional<MapSnapshot> snapshot = takeSnapshot();
  return snapshot ? std::move(snapshot->map) : nullptr;
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
  idle_.wait(lock, [this] { return !working_ && !releasing_ && !prefetching_ && queue_.empty() && retired_.empty(); });
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

namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// CPU time of the calling thread [ms]: on a shared machine, what loading costs one core.
double threadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return 1e3 * ts.tv_sec + 1e-6 * ts.tv_nsec;
}

// Runs work() and adds its wall time and the calling thread's CPU time [ms] to the two totals.
template <typename Work>
void timed(double& wall_ms, double& cpu_ms, Work&& work) {
  const auto start = Clock::now();
  const double cpu = threadCpuMs();
  work();
  cpu_ms += threadCpuMs() - cpu;
  wall_ms += msSince(start);
}

constexpr std::size_t kFoldBatchPoints = 1 << 21;  // ~2 M points read per fold, their voxels waiting meanwhile

std::string withoutTrailingSlash(std::string url) {
  while (url.size() > 1 && url.back() == '/') url.pop_back();
  return url;
}

// Tiles a map store fetches at once (its parallel requests; before its first fetch, its connections).
std::size_t fetchRound(const MapStore& store) {
  return static_cast<std::size_t>(std::max(1, store.status().parallel_requests));
}

bool isDirectory(const std::string& path) {
  struct stat st;
  return ::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode);
}

}  // namespace

void MapUpdateWorker::apply(NdtTarget& target, const MapChange& change, std::vector<std::string>& failures) {
  window_ = change.kind == MapChange::Kind::kTileFiles ? change.files.window : std::nullopt;
  switch (change.kind) {
    case MapChange::Kind::kFullCloud:
      target.setTarget(change.cloud);
      tiles_.clear();
      break;
    case MapChange::Kind::kPcdFile:
      target.setTarget(readPcdXyz(change.pcd_path));
      tiles_.clear();
      break;
    case MapChange::Kind::kTiles:
      startTiles(target, change.reset, change.grid_size);
      removeTiles(target, change.removed);
      {
        std::vector<PendingTile> batch;
        for (const TileCloud& tile : change.added) {
          try {
            batch.push_back(pendingTile(tile.id, tile.points));
          } catch (const std::invalid_argument& e) {
            failures.emplace_back(e.what());
          }
        }
        addTiles(target, batch);
      }
      break;
    case MapChange::Kind::kTileFiles:
      applyTileFiles(target, change.grid_size, change.files, failures);
      break;
  }
}

void MapUpdateWorker::startTiles(NdtTarget& target, bool reset, double grid_size) {
  if (!reset && !tiles_.empty() && grid_size != tile_size_)
    throw std::invalid_argument("tile side changed from " + std::to_string(tile_size_) + " m to " +
                                std::to_string(grid_size) + " m without a reset; change ignored");
  if (reset) {
    target.setTarget(PointCloud());
    tiles_.clear();
  }
  if (tiles_.empty()) {
    tile_size_ = grid_size;
    aligned_ = voxelsPerTileSide(grid_size, params_.resolution) > 0;
  }
}

void MapUpdateWorker::removeTiles(NdtTarget& target, const std::vector<std::string>& ids) {
  std::vector<TileKey> aligned;
  for (const std::string& id : ids) {
    const auto it = tiles_.find(id);
    if (it == tiles_.end()) continue;
    if (aligned_)
      aligned.push_back(it->second.key);
    else
      target.removeTarget(it->second.id);
    tiles_.erase(it);
  }
  if (!aligned.empty()) target.removeTiles(aligned, tile_size_);
}

MapUpdateWorker::PendingTile MapUpdateWorker::pendingTile(const std::string& id, PointCloud points) const {
  PendingTile tile;
  tile.id = id;
  if (aligned_)
    tile.voxels = tileVoxels(tileKeyOfStem(id, tile_size_), tile_size_, params_.resolution, points);
  else
    tile.points = std::move(points);
  return tile;
}

void MapUpdateWorker::addTiles(NdtTarget& target, const std::vector<PendingTile>& batch) {
  std::vector<std::string> reloaded;
  for (const PendingTile& tile : batch)
    if (tiles_.count(tile.id)) reloaded.push_back(tile.id);
  removeTiles(target, reloaded);
  std::vector<const TileVoxels*> aligned;
  for (const PendingTile& tile : batch) {
    if (tiles_.count(tile.id)) continue;  // twice in one batch: the first copy counts
    LoadedTile loaded;
    if (aligned_) {
      loaded.key = tile.voxels.key;
      aligned.push_back(&tile.voxels);
    } else {
      loaded.id = next_id_++;
      target.addTarget(loaded.id, tile.points);
    }
    tiles_.emplace(tile.id, loaded);
  }
  if (!aligned.empty()) totals_.points_outside += target.addTileVoxels(aligned);
}

PointCloud MapUpdateWorker::readTile(const std::string& path) {
  PointCloud points;
  timed(totals_.tile_read_ms, totals_.tile_read_cpu_ms, [&] { points = readPcdXyz(path); });
  ++totals_.tiles_read;
  totals_.tile_points_read += points.size();
  return points;
}

void MapUpdateWorker::copyStoreStatus() {
  if (!store_) return;
  const MapStoreStatus store = store_->status();
  stats_.map_store_reachable = store.reachable;
  stats_.map_store_error = store.reachable ? "" : "map store " + store.url + " unreachable: " + store.last_error;
  stats_.map_store_fetched = store.tiles_fetched;
  stats_.map_store_bytes = store.bytes_fetched;
}

MapStore& MapUpdateWorker::storeAt(const std::string& url, const std::string& revision) {
  if (!store_ || store_->url() != withoutTrailingSlash(url)) {
    MapStoreConfig config;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      config = store_config_;
    }
    store_.reset();
    store_ = std::make_unique<MapStore>(url, config);  // fetches the index (network, on this thread)
  }
  if (store_->status().revision != revision) store_->pollIndex();
  const std::string held = store_->status().revision;
  if (held != revision)
    throw std::invalid_argument(
        "map store " + store_->url() + ": its index is at revision '" + held + "', the change names '" + revision +
        "'; keeping the " + std::to_string(tiles_.size()) +
        " tiles loaded until the provider sends the reset of the server's revision" +
        (store_->status().last_error.empty() ? "" : " (last error: " + store_->status().last_error + ")"));
  return *store_;
}

void MapUpdateWorker::applyTileFiles(NdtTarget& target, double grid_size, const TileFileChange& change,
                                     std::vector<std::string>& failures) {
  const bool remote = isMapStoreUrl(change.dir);
  // A directory given by URL: every tile of this change is checked against the index of exactly this revision, so
  // tiles of two revisions never meet in one target.
  MapStore* store = remote ? &storeAt(change.dir, change.index_revision) : nullptr;
  if (!remote && !isDirectory(change.dir))
    throw std::invalid_argument("tile directory '" + change.dir + "' does not exist; keeping the " +
                                std::to_string(tiles_.size()) + " tiles loaded (check the provider's tiles/dir)");
  const bool same_source = fromHeldSource(change);
  if (!change.reset && !same_source)
    throw std::invalid_argument("tile directory '" + change.dir + "' (index revision '" + change.index_revision +
                                "') is not the one the loaded tiles came from ('" + tile_dir_ + "', revision '" +
                                index_revision_ + "') and the change is not a reset; change ignored");
  if (!same_source) cache_.clear();  // cached tiles of another directory or revision are other tiles
  std::vector<std::string> added = change.added;
  std::vector<std::string> removed = change.removed;
  const bool keep_held = keepsHeldTiles(change, grid_size);
  if (keep_held) {
    // The whole window again from the source the held tiles came from (a respawned provider, a resend): the held
    // tiles it names stay, the others leave, and only the tiles not held are read (one that failed is read again).
    const std::unordered_set<std::string> named(change.added.begin(), change.added.end());
    added.clear();
    removed.clear();
    for (const std::string& id : change.added)
      if (!tiles_.count(id)) added.push_back(id);
    for (const auto& held : tiles_)
      if (!named.count(held.first)) removed.push_back(held.first);
  }
  startTiles(target, change.reset && !keep_held, grid_size);
  tile_dir_ = change.dir;
  index_revision_ = change.index_revision;
  prefetch_.assign(change.prefetch.rbegin(), change.prefetch.rend());  // read from the back: first id first
  removeTiles(target, removed);
  // Tiles are folded in batches of about kFoldBatchPoints: one target update (each touched shard copied once) per
  // batch instead of per tile, while what waits to be folded stays bounded.
  std::vector<PendingTile> pending;
  std::size_t pending_points = 0;
  const auto fold = [&] {
    timed(totals_.tile_fold_ms, totals_.tile_fold_cpu_ms, [&] { addTiles(target, pending); });
    for (const PendingTile& tile : pending) landed(tile.id);
    pending.clear();
    pending_points = 0;
  };
  // From a map store, tiles come in batches fetched concurrently into its disk cache, each read before the next
  // batch is fetched (a fetched file is kept until the store's next fetch).
  std::unordered_map<std::string, FetchedTile> fetched;
  // Tiles of the window that could not be fetched (server down, a bad copy on it) are asked for again with the
  // next changes of the same source, one fetch batch per change, the latest failures (nearest the vehicle) first:
  // after an outage the backlog drains over the next changes instead of holding back the first one, and the
  // target, for seconds. A reset names the whole window anyway.
  std::vector<std::string> deferred;
  if (store && same_source && !change.reset) {
    const std::unordered_set<std::string> leaving(change.removed.begin(), change.removed.end());
    std::size_t retried = 0;
    for (auto id = refetch_.rbegin(); id != refetch_.rend(); ++id) {
      if (leaving.count(*id) || tiles_.count(*id)) continue;
      (retried++ < kTileFetchBatch ? added : deferred).push_back(*id);
    }
  }
  refetch_.assign(deferred.rbegin(), deferred.rend());  // oldest first, as they failed
  // One fetch batch (or, from disk, as many tiles) at a time, nearest the newest predicted position first: a change
  // that takes seconds to arrive follows a pose that moves meanwhile.
  NearestFirstTiles left(added, grid_size);
  // From a map store, a batch is as many tiles as its server delivered in kPartialSnapshotPeriod (at least a round of
  // its parallel requests, at most kTileFetchBatch), so a slow server's tiles are matched on as they come; the first
  // batch is one round.
  std::size_t batch_size = store ? fetchRound(*store) : kTileFetchBatch;
  while (!left.empty()) {
    // Changes of this source queued meanwhile (the window moved on while this one loads) join it: what leaves goes
    // now, loaded or not, and what enters joins the tiles still to load, nearest the focus first. What the vehicle
    // needs next does not wait behind the rest of this change, and is known to be in flight at once.
    const std::deque<MapChange> joining = takeJoining(grid_size, change);
    if (!joining.empty()) {
      fold();  // a tile read but not folded yet may be leaving
      planInFlight(joining);
      for (const MapChange& next : joining) {
        removeTiles(target, next.files.removed);
        left.remove(next.files.removed);
        left.add(next.files.added);
        window_ = next.files.window;
        prefetch_.assign(next.files.prefetch.rbegin(), next.files.prefetch.rend());
      }
      announceInFlight();
    }
    const std::vector<std::string> chunk = left.take(batch_size, focus());
    if (store) {
      std::vector<std::string> batch;
      for (const std::string& id : chunk)
        if (!(aligned_ && cache_.contains(change.dir + "/" + id + ".pcd"))) batch.push_back(id);
      fetched.clear();
      const auto fetch_start = Clock::now();
      for (FetchedTile& t : store->fetch(batch)) fetched[t.id] = std::move(t);
      const double seconds = std::chrono::duration<double>(Clock::now() - fetch_start).count();
      if (!batch.empty() && seconds > 0.0)
        batch_size = std::clamp(static_cast<std::size_t>(batch.size() / seconds * kPartialSnapshotPeriod),
                                fetchRound(*store), kTileFetchBatch);
      std::lock_guard<std::mutex> lock(mutex_);
      copyStoreStatus();  // a server that answers again is reported at once, not after the whole change
    }
    for (const std::string& id : chunk) {
      const std::string path = change.dir + "/" + id + ".pcd";  // the prefetch cache's key (a URL for a map store)
      try {
        std::optional<TileVoxels> cached = aligned_ ? cache_.take(path) : std::nullopt;
        if (cached) {
          ++totals_.cache_hits;
          PendingTile tile;
          tile.id = id;
          tile.voxels = std::move(*cached);
          pending.push_back(std::move(tile));
        } else {
          std::string file = path;
          if (store) {
            const auto t = fetched.find(id);
            if (t == fetched.end() || t->second.path.empty()) {
              refetch_.push_back(id);
              throw std::runtime_error(t == fetched.end() ? "not fetched from " + change.dir : t->second.error);
            }
            file = t->second.path;
          }
          PointCloud points = readTile(file);
          pending_points += points.size();
          timed(totals_.tile_fold_ms, totals_.tile_fold_cpu_ms,
                [&] { pending.push_back(pendingTile(id, std::move(points))); });
        }
      } catch (const std::exception& e) {  // PcdReadError names the file; a bad id says what a tile name is
        failures.push_back("tile " + id + " skipped: " + e.what());
        landed(id);
      }
      if (pending_points >= kFoldBatchPoints) fold();
    }
    // What has arrived is matched on while the rest comes, nearest the vehicle first.
    if (!left.empty() && Clock::now() - published_ >= std::chrono::duration<double>(kPartialSnapshotPeriod)) {
      fold();
      publish(target, true, 0.0, 0, failures);
    }
  }
  fold();
}

bool MapUpdateWorker::fromHeldSource(const TileFileChange& change) const {
  return change.dir == tile_dir_ && change.index_revision == index_revision_;
}

bool MapUpdateWorker::keepsHeldTiles(const TileFileChange& change, double grid_size) const {
  return change.reset && !tiles_.empty() && grid_size == tile_size_ && fromHeldSource(change);
}

void MapUpdateWorker::planInFlight(const std::deque<MapChange>& batch) {
  const auto enter = [this](const std::string& id, double grid_size) {
    try {
      in_flight_.emplace(id, tileKeyOfStem(id, grid_size));
    } catch (const std::invalid_argument&) {
      // Not a tile name: loading it reports why.
    }
  };
  for (const MapChange& change : batch) {
    const bool tiles = change.kind == MapChange::Kind::kTiles;
    if (!tiles && change.kind != MapChange::Kind::kTileFiles) {  // a whole map
      in_flight_.clear();
      continue;
    }
    if ((tiles ? change.reset : change.files.reset) || change.grid_size != in_flight_size_) in_flight_.clear();
    in_flight_size_ = change.grid_size;
    for (const std::string& id : tiles ? change.removed : change.files.removed) in_flight_.erase(id);
    if (tiles) {
      for (const TileCloud& tile : change.added) enter(tile.id, change.grid_size);
      continue;
    }
    const bool keep_held = keepsHeldTiles(change.files, change.grid_size);  // the held tiles are not read again
    for (const std::string& id : change.files.added)
      if (!keep_held || !tiles_.count(id)) enter(id, change.grid_size);
  }
}

std::deque<MapChange> MapUpdateWorker::takeJoining(double grid_size, const TileFileChange& change) {
  std::deque<MapChange> out;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    while (!queue_.empty()) {
      const MapChange& next = queue_.front();
      if (next.kind != MapChange::Kind::kTileFiles || next.grid_size != grid_size || next.files.reset ||
          next.files.dir != change.dir || next.files.index_revision != change.index_revision)
        break;
      out.push_back(std::move(queue_.front()));
      queue_.pop_front();
    }
  }
  joined_.insert(joined_.end(), out.begin(), out.end());
  return out;
}

void MapUpdateWorker::landed(const std::string& id) { in_flight_.erase(id); }

TilesInFlight MapUpdateWorker::inFlight() const {
  TilesInFlight out{in_flight_size_, {}};
  out.keys.reserve(in_flight_.size());
  for (const auto& tile : in_flight_) out.keys.push_back(tile.second);
  return out;
}

void MapUpdateWorker::announceInFlight() {
  TilesInFlight in_flight = inFlight();
  std::lock_guard<std::mutex> lock(mutex_);
  if (ready_)
    ready_->in_flight = std::move(in_flight);  // with the map not taken yet
  else
    ready_ = MapSnapshot{nullptr, std::move(in_flight)};
}

void MapUpdateWorker::publish(const NdtTarget& target, bool partial, double update_ms, std::size_t changes,
                              std::vector<std::string>& failures) {
  MapSnapshot snapshot{target.snapshot(), inFlight()};
  const VoxelMap& map = *snapshot.map;
  std::lock_guard<std::mutex> lock(mutex_);
  if (partial) {
    ++stats_.partial_snapshots;
  } else {
    ++stats_.generation;
    stats_.update_ms = update_ms;
    stats_.changes = changes;
  }
  stats_.tiles = tiles_.size();
  stats_.window = window_;
  stats_.tile_aligned = aligned_;
  stats_.voxels = map.gaussianCount();
  stats_.points = map.pointCount();
  stats_.map_bytes = map.bytes();
  errors_.insert(errors_.end(), failures.begin(), failures.end());
  failures.clear();
  ready_ = std::move(snapshot);
  published_ = Clock::now();
}

void MapUpdateWorker::readAhead() {
  for (;;) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (stop_ || !queue_.empty() || prefetch_.empty()) return;
      cache_.setBudget(cache_budget_);
    }
    const std::string id = prefetch_.back();
    prefetch_.pop_back();
    const std::string path = tile_dir_ + "/" + id + ".pcd";
    // Read ahead keeps a tile's voxel statistics; without tile-aligned voxels there are none to keep.
    if (!aligned_ || tiles_.count(id) || cache_.contains(path) || cache_.budget() == 0) continue;
    try {
      std::string file = path;
      if (isMapStoreUrl(tile_dir_)) {
        // The store of the loaded tiles (their revision); one tile at a time, so a queued change waits little.
        if (!store_ || store_->url() != withoutTrailingSlash(tile_dir_)) continue;
        const FetchedTile t = store_->fetch({id}).front();
        if (t.path.empty()) continue;
        file = t.path;
      }
      cache_.put(path, pendingTile(id, readTile(file)).voxels);
    } catch (const std::exception&) {
      // Reported when the tile enters the window and is read again.
    }
  }
}

namespace {

// glibc keeps freed heap pages resident until malloc_trim hands them back. Map updates free tile clouds and
// shard copies, so without a trim the process would keep its high-water mark. A trim after every window update
// costs more than it returns, though: the next update, the next scan message and its filtering fault the same
// pages in again, and the kernel zeroes each one (on the urban drive, four updates a second, about 1 % of a
// core). So the worker trims after its first change (the start-up map) and then at most once per
// kTrimPeriod, also when it goes idle with freed memory not yet handed back.
constexpr auto kTrimPeriod = std::chrono::seconds(2);

// malloc_trim hands back free pages inside an arena's heap but never the top of a thread's own arena (the
// worker's), and glibc's dynamic thresholds let that top keep up to twice the largest block it has freed: a whole
// retired map, seen on a busy machine. Fixed thresholds bound it: blocks of kHeapBlockLimit or more are mapped
// apart and go back when freed, and a free leaving more than that at an arena's top trims it. The per-scan cost
// (64-beam KITTI-00 scans through bench_localizer) is within the repeat noise. The setting is the process's, made
// once, by the first worker.
constexpr int kHeapBlockLimit = 1 << 20;

void pinHeapThresholds() {
#if defined(__GLIBC__)
  static std::once_flag once;
  std::call_once(once, [] {
    mallopt(M_MMAP_THRESHOLD, kHeapBlockLimit);
    mallopt(M_TRIM_THRESHOLD, kHeapBlockLimit);
  });
#endif
}

// When the worker hands freed heap back to the system: right after the first change, then at most once per
// kTrimPeriod.
class HeapTrimmer {
 public:
  /// Memory was freed: a trim is due once the period since the last one is over.
  void freed() { pending_ = true; }
  bool pending() const { return pending_; }
  Clock::time_point due() const { return last_ + kTrimPeriod; }
  void trimIfDue() {
    if (!pending_ || Clock::now() < due()) return;
#if defined(__GLIBC__)
    malloc_trim(0);
#endif
    last_ = Clock::now();
    pending_ = false;
  }

 private:
  Clock::time_point last_;  // the epoch: the first change is trimmed at once
  bool pending_ = false;
};

}  // namespace

void MapUpdateWorker::run() {
  lowerCallingThreadPriority(kWorkerNiceIncrement);
  pinHeapThresholds();
  NdtTarget target(params_);
  std::unique_lock<std::mutex> lock(mutex_);
  HeapTrimmer trimmer;
  for (;;) {
    const auto has_work = [this] { return stop_ || !queue_.empty() || !retired_.empty(); };
    if (!trimmer.pending()) {
      wake_.wait(lock, has_work);
    } else if (!wake_.wait_until(lock, trimmer.due(), has_work)) {
      lock.unlock();
      trimmer.trimIfDue();
      lock.lock();
      continue;
    }
    if (stop_) return;
    std::deque<MapChange> batch;
    batch.swap(queue_);
    std::vector<std::shared_ptr<const VoxelMap>> retired;
    retired.swap(retired_);
    working_ = !batch.empty();
    releasing_ = !retired.empty();
    const std::size_t budget = cache_budget_;
    lock.unlock();

    // Old snapshots the scan thread handed back are freed here (when no other holder is left).
    retired.clear();
    cache_.setBudget(budget);
    if (!batch.empty()) {
      const auto start = Clock::now();
      planInFlight(batch);
      if (!in_flight_.empty()) announceInFlight();  // known as missing before the first of them arrives
      std::vector<std::string> failures;
      for (const MapChange& change : batch) {
        try {
          apply(target, change, failures);
        } catch (const std::exception& e) {
          failures.emplace_back(e.what());
        }
        // Whatever of the change has not landed by now will not come with it (a failure says why).
        for (const TileCloud& tile : change.added) landed(tile.id);
        for (const std::string& id : change.files.added) landed(id);
      }
      for (const MapChange& change : joined_)
        for (const std::string& id : change.files.added) landed(id);
      const std::size_t changes = batch.size() + joined_.size();
      joined_.clear();
      publish(target, false, msSince(start), changes, failures);
    }

    lock.lock();
    working_ = false;
    releasing_ = false;
    prefetching_ = !prefetch_.empty();
    // Freeing the applied batch (large clouds) is the worker's job, not the scan thread's.
    lock.unlock();
    batch.clear();
    readAhead();
    trimmer.freed();
    trimmer.trimIfDue();
    lock.lock();
    prefetching_ = false;
    stats_.tiles_read = totals_.tiles_read;
    stats_.tile_points_read = totals_.tile_points_read;
    stats_.tile_read_ms = totals_.tile_read_ms;
    stats_.tile_fold_ms = totals_.tile_fold_ms;
    stats_.tile_read_cpu_ms = totals_.tile_read_cpu_ms;
    stats_.tile_fold_cpu_ms = totals_.tile_fold_cpu_ms;
    stats_.cache_hits = totals_.cache_hits;
    stats_.points_outside = totals_.points_outside;
    stats_.cache_bytes = cache_.bytes();
    stats_.worker_cpu_ms = threadCpuMs();
    copyStoreStatus();
    if (queue_.empty() && retired_.empty()) idle_.notify_all();
  }
}

}  // namespace grid_puzzle_localization
