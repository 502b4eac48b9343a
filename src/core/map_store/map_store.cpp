#include "grid_puzzle_localization/map_store/map_store.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <unordered_map>

#include "disk_cache.hpp"
#include "http_client.hpp"
#include "map_store_backend.hpp"

namespace grid_puzzle_localization {

using map_store_detail::DiskCache;
using map_store_detail::HttpClient;
using map_store_detail::HttpGet;
using map_store_detail::HttpResult;
using map_store_detail::makeDirectories;
using map_store_detail::readWholeFile;
using map_store_detail::writeFileAtomically;

namespace {

constexpr const char* kIndexFile = "index.json";

// The URL without a trailing '/', or std::invalid_argument saying what is wrong with it.
std::string checkedUrl(const std::string& url) {
  const auto bad = [&](const std::string& why) { return std::invalid_argument("map store URL '" + url + "': " + why); };
  const std::size_t scheme_end = url.find("://");
  if (!isMapStoreUrl(url)) throw bad("only http:// and https:// are supported");
  for (const char c : url)
    if (static_cast<unsigned char>(c) <= ' ' || c == 0x7f) throw bad("it holds white space or control characters");
  if (url.find_first_of("?#") != std::string::npos)
    throw bad("a query or fragment cannot be extended with tile names; give the directory's URL");
  const std::size_t host_end = url.find('/', scheme_end + 3);
  const std::string authority =
      url.substr(scheme_end + 3, host_end == std::string::npos ? std::string::npos : host_end - scheme_end - 3);
  if (authority.empty()) throw bad("no host");
  if (authority.find('@') != std::string::npos)
    throw bad("credentials in the URL would be logged; use map_store/bearer_token_file or basic_auth_file");
  std::string out = url;
  while (out.size() > scheme_end + 3 && out.back() == '/') out.pop_back();
  return out;
}

std::string defaultCacheRoot() {
  const char* xdg = std::getenv("XDG_CACHE_HOME");
  const char* home = std::getenv("HOME");
  const std::string base = xdg && *xdg ? xdg : std::string(home && *home ? home : "/tmp") + "/.cache";
  return base + "/grid_puzzle_localization/map_store";
}

bool retryable(const HttpResult& r) {
  if (r.too_large) return false;
  if (!r.transferred) return true;  // no connection, timeout, connection cut mid-body
  return r.status == 408 || r.status == 429 || r.status >= 500;
}

// The state of one store.
struct StoreState {
  std::string url;
  MapStoreConfig config;
  std::string dir;  // this URL's cache directory
  std::unique_ptr<HttpClient> client;
  std::unique_ptr<DiskCache> tiles;
  TileIndexListing index;
  std::unordered_map<std::string, std::size_t> by_stem;  // stem -> position in index.tiles
  std::string etag, revision;
  mutable std::mutex status_mutex;  // status() may be asked from another thread
  MapStoreStatus status;

  std::string indexUrl() const { return url + "/" + kIndexFile; }

  void fail(const std::string& error, bool reached) {
    std::lock_guard<std::mutex> lock(status_mutex);
    status.last_error = error;
    status.reachable = reached;
    ++status.failed_attempts;
  }
  void reached() {
    std::lock_guard<std::mutex> lock(status_mutex);
    status.reachable = true;
  }
  bool reachable() const {
    std::lock_guard<std::mutex> lock(status_mutex);
    return status.reachable;
  }

  // Makes `text` (index.json of this URL) the index in use; std::invalid_argument naming the URL when it is not
  // a tile index or names a tile unsafely.
  void use(const std::string& text, const std::string& what) {
    TileIndexListing listing = parseTileIndex(text, what);
    std::unordered_map<std::string, std::size_t> stems;
    for (std::size_t k = 0; k < listing.tiles.size(); ++k) {
      const std::string& file = listing.tiles[k].file;
      const std::string why = unsafeTileName(file);
      if (!why.empty() || file.size() < 5 || file.compare(file.size() - 4, 4, ".pcd") != 0)
        throw std::invalid_argument(what + ": tile file name '" + file.substr(0, 100) + "' is refused (" +
                                    (why.empty() ? "not a .pcd file" : why) +
                                    "); an index may only name files beside it");
      stems.emplace(file.substr(0, file.size() - 4), k);
    }
    index = std::move(listing);
    by_stem = std::move(stems);
    revision = "sha256:" + sha256Hex(text).substr(0, 16);
    std::lock_guard<std::mutex> lock(status_mutex);
    status.revision = revision;
  }

  // One request with up to max_retries retries (backoff doubling); only one attempt while the server is known to be
  // unreachable, so an offline store does not stall its caller.
  HttpResult getWithRetries(const HttpGet& request) {
    HttpResult r;
    const int attempts = reachable() ? 1 + config.max_retries : 1;
    for (int attempt = 0; attempt < attempts; ++attempt) {
      if (attempt > 0) pause(attempt);
      r = client->get({request}).front();
      count(r);
      if (!retryable(r)) break;
      fail(request.url + ": " + describe(r), r.reached);
    }
    if (!retryable(r)) reached();
    return r;
  }

  void pause(int attempt) const {
    std::this_thread::sleep_for(std::chrono::duration<double>(config.retry_backoff * std::ldexp(1.0, attempt - 1)));
  }

  void count(const HttpResult& r) {
    std::lock_guard<std::mutex> lock(status_mutex);
    status.connections_opened += static_cast<std::size_t>(r.connects);
    status.parallel_requests = client->parallelRequests();
  }

  static std::string describe(const HttpResult& r) {
    if (!r.transferred) return r.error;
    return "HTTP " + std::to_string(r.status);
  }

  // Polls index.json; true when a new revision is in use. Throws (invalid index) only when `strict`.
  bool poll(bool strict) {
    HttpGet request{indexUrl(), index.tiles.empty() ? "" : etag, config.max_index_bytes};
    const HttpResult r = getWithRetries(request);
    if (r.transferred && r.status == 304) return false;
    if (!r.transferred || r.status != 200) {
      const std::string error =
          "cannot fetch " + request.url + ": " + describe(r) + (r.too_large ? " (map_store/max_index_bytes)" : "");
      fail(error, r.reached);
      if (strict) throw std::invalid_argument(error);
      return false;
    }
    const std::string new_revision = "sha256:" + sha256Hex(r.body).substr(0, 16);
    if (new_revision == revision && !index.tiles.empty()) {
      etag = r.etag;
      return false;
    }
    try {
      use(r.body, request.url);
    } catch (const std::invalid_argument& e) {
      fail(e.what(), true);
      if (strict) throw;
      return false;
    }
    etag = r.etag;
    writeFileAtomically(dir + "/" + kIndexFile, r.body);
    writeFileAtomically(dir + "/index.etag", etag);
    return true;
  }

  // Cache file name of tile `entry`: its checksum (a changed tile is another file, an unchanged one is kept across
  // revisions), or the revision and its name for an index without checksums.
  std::string cacheName(const TileIndexEntry& entry) const {
    return entry.sha256.empty() ? revision.substr(7) + "-" + entry.file : entry.sha256 + ".pcd";
  }

  // "" when `bytes` is tile `entry` as the index says, else why not.
  static std::string mismatch(const TileIndexEntry& entry, const std::string& bytes) {
    if (bytes.size() != entry.bytes)
      return std::to_string(bytes.size()) + " bytes where the index says " + std::to_string(entry.bytes) +
             (bytes.size() < entry.bytes ? " (truncated)" : "");
    if (!entry.sha256.empty() && sha256Hex(bytes) != entry.sha256)
      return "its SHA-256 does not match the index (corrupt, or the map changed on the server)";
    return "";
  }
};

// The store over libcurl: what MapStore forwards to.
class HttpMapStore final : public map_store_detail::Backend {
 public:
  HttpMapStore(const std::string& url, const MapStoreConfig& config);
  bool pollIndex() override { return m.poll(false); }
  std::vector<FetchedTile> fetch(const std::vector<std::string>& ids) override;
  const std::string& url() const override { return m.url; }
  const TileIndexListing& index() const override { return m.index; }
  std::string indexPath() const override { return m.dir + "/" + kIndexFile; }
  std::string cacheDirectory() const override { return m.dir; }
  MapStoreStatus status() const override {
    std::lock_guard<std::mutex> lock(m.status_mutex);
    return m.status;
  }

 private:
  StoreState m;
};

HttpMapStore::HttpMapStore(const std::string& url, const MapStoreConfig& config) {
  m.url = checkedUrl(url);
  const std::string problem = config.validate();
  if (!problem.empty()) throw std::invalid_argument("map store " + m.url + ": " + problem);
  m.config = config;
  m.status.url = m.url;
  const std::string root = config.cache_dir.empty() ? defaultCacheRoot() : config.cache_dir;
  m.dir = root + "/" + sha256Hex(m.url).substr(0, 16);
  makeDirectories(m.dir);
  writeFileAtomically(m.dir + "/url", m.url + "\n");  // which map a directory holds, for a person looking
  m.client = std::make_unique<HttpClient>(config);
  m.status.parallel_requests = m.client->parallelRequests();
  m.tiles = std::make_unique<DiskCache>(m.dir + "/tiles", config.cache_max_bytes);
  m.status.cache_bytes = m.tiles->bytes();
  // The index a previous run kept: the store can start offline on it.
  std::string cached;
  if (readWholeFile(m.dir + "/" + kIndexFile, cached)) {
    try {
      m.use(cached, m.dir + "/" + kIndexFile);
      readWholeFile(m.dir + "/index.etag", m.etag);
    } catch (const std::invalid_argument&) {
      m.index = TileIndexListing();
    }
  }
  const bool have_cached = !m.index.tiles.empty();
  try {
    m.poll(true);
  } catch (const std::invalid_argument& e) {
    if (!have_cached || m.reachable())
      throw std::invalid_argument(std::string(e.what()) +
                                  (have_cached ? "" : "; the cache " + m.dir + " holds no index of it either") +
                                  "; check the URL and that the server runs");
    // Unreachable, with a cached index: track on what the cache holds; fetch() and pollIndex() try again.
  }
  if (m.index.tiles.empty())
    throw std::invalid_argument("map store " + m.url +
                                ": its index lists no tiles; re-run `gpm tile` on a non-empty map");
}

std::vector<FetchedTile> HttpMapStore::fetch(const std::vector<std::string>& ids) {
  m.tiles->unpinAll();
  std::vector<FetchedTile> out(ids.size());
  std::vector<std::size_t> missing;  // positions in `out` to download
  for (std::size_t k = 0; k < ids.size(); ++k) {
    FetchedTile& t = out[k];
    t.id = ids[k];
    const std::string why = unsafeTileName(t.id);
    const auto found = why.empty() ? m.by_stem.find(t.id) : m.by_stem.end();
    if (found == m.by_stem.end()) {
      t.error = "tile '" + t.id.substr(0, 100) + "' " +
                (why.empty() ? "is not in the index of " + m.url + " (revision " + m.revision + ")"
                             : "is refused (" + why + ")");
      continue;
    }
    const TileIndexEntry& entry = m.index.tiles[found->second];
    if (entry.bytes > m.config.max_tile_bytes) {
      t.error = m.url + "/" + entry.file + ": " + std::to_string(entry.bytes) +
                " bytes, more than map_store/max_tile_bytes " + std::to_string(m.config.max_tile_bytes) + "; refused";
      continue;
    }
    const std::string name = m.cacheName(entry);
    std::string bytes;
    if (m.tiles->touch(name)) {
      if (readWholeFile(m.tiles->pathOf(name), bytes) && StoreState::mismatch(entry, bytes).empty()) {
        t.path = m.tiles->pathOf(name);
        m.tiles->pin(name);
        std::lock_guard<std::mutex> lock(m.status_mutex);
        ++m.status.cache_hits;
        continue;
      }
      m.tiles->remove(name);  // damaged on disk: fetched again
    }
    missing.push_back(k);
  }
  const int attempts = m.reachable() ? 1 + m.config.max_retries : 1;
  for (int attempt = 0; attempt < attempts && !missing.empty(); ++attempt) {
    if (attempt > 0) m.pause(attempt);
    std::vector<HttpGet> requests;
    for (const std::size_t k : missing) {
      const TileIndexEntry& entry = m.index.tiles[m.by_stem.at(out[k].id)];
      requests.push_back({m.url + "/" + entry.file, "", std::min<std::uint64_t>(entry.bytes, m.config.max_tile_bytes)});
    }
    const std::vector<HttpResult> results = m.client->get(requests);
    std::vector<std::size_t> again;
    bool any_reached = false;
    for (std::size_t r = 0; r < results.size(); ++r) {
      const HttpResult& res = results[r];
      FetchedTile& t = out[missing[r]];
      const TileIndexEntry& entry = m.index.tiles[m.by_stem.at(t.id)];
      m.count(res);
      any_reached = any_reached || res.reached;
      std::string why;
      bool retry = false;
      if (res.too_large) {
        why = "larger than the index's " + std::to_string(entry.bytes) + " bytes; refused before it was stored";
      } else if (!res.transferred || res.status != 200) {
        why = StoreState::describe(res);
        retry = retryable(res);
      } else {
        why = StoreState::mismatch(entry, res.body);
        retry = !why.empty();  // a CDN edge may serve a stale copy for a moment
      }
      if (why.empty()) {
        const std::string name = m.cacheName(entry);
        try {
          m.tiles->store(name, res.body);
          m.tiles->pin(name);
          t.path = m.tiles->pathOf(name);
          t.error.clear();
          std::lock_guard<std::mutex> lock(m.status_mutex);
          ++m.status.tiles_fetched;
          m.status.bytes_fetched += res.body.size();
        } catch (const std::runtime_error& e) {
          t.error = e.what();
        }
        continue;
      }
      t.error = requests[r].url + ": " + why;
      m.fail(t.error, res.reached);
      if (retry) again.push_back(missing[r]);
    }
    if (any_reached) m.reached();
    missing.swap(again);
  }
  m.tiles->evict();
  std::lock_guard<std::mutex> lock(m.status_mutex);
  m.status.cache_bytes = m.tiles->bytes();
  return out;
}

}  // namespace

}  // namespace grid_puzzle_localization

extern "C" grid_puzzle_localization::map_store_detail::Backend* gpl_open_map_store(
    const std::string& url, const grid_puzzle_localization::MapStoreConfig& config) {
  return new grid_puzzle_localization::HttpMapStore(url, config);
}
