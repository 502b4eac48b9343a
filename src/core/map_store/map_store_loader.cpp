// MapStore in the core: the URL and name checks, and the forwarding to the map store library, loaded on first use so
// that a process on a local map never maps libcurl and its TLS libraries.
#include <dlfcn.h>

#include <cmath>
#include <mutex>
#include <stdexcept>

#include "map_store_backend.hpp"

// Non-null when the map store library is linked into the process (its tests and benchmarks, static builds).
#pragma weak gpl_open_map_store

namespace grid_puzzle_localization {
namespace {

using OpenFunction = decltype(&gpl_open_map_store);

bool startsWith(const std::string& s, const char* prefix) { return s.rfind(prefix, 0) == 0; }

// The map store library beside the core's own (devel or install space), else by name on the library path.
OpenFunction loadMapStoreLibrary() {
  std::string path = GPL_MAP_STORE_LIBRARY;
  Dl_info self{};
  // This function's own address (internal linkage: never an executable's stub) names the core's library file.
  if (dladdr(reinterpret_cast<void*>(&loadMapStoreLibrary), &self) != 0 && self.dli_fname != nullptr) {
    const std::string core = self.dli_fname;
    const std::size_t slash = core.rfind('/');
    if (slash != std::string::npos) path = core.substr(0, slash + 1) + GPL_MAP_STORE_LIBRARY;
  }
  void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);  // kept open: stores may live until exit
  if (handle == nullptr && path != GPL_MAP_STORE_LIBRARY) handle = dlopen(GPL_MAP_STORE_LIBRARY, RTLD_NOW | RTLD_LOCAL);
  if (handle == nullptr)
    throw std::runtime_error(std::string("cannot load the map store library ") + path + " (" + dlerror() +
                             "); the package is incomplete: rebuild it (make build) or reinstall it");
  void* open = dlsym(handle, "gpl_open_map_store");
  if (open == nullptr)
    throw std::runtime_error("the map store library " + path +
                             " has no gpl_open_map_store; it is of another build: rebuild the package");
  return reinterpret_cast<OpenFunction>(open);
}

OpenFunction mapStoreOpener() {
  if (gpl_open_map_store != nullptr) return &gpl_open_map_store;
  static std::once_flag once;
  static OpenFunction open = nullptr;
  std::call_once(once, [] { open = loadMapStoreLibrary(); });  // a failed load throws and is tried again next time
  return open;
}

}  // namespace

bool isMapStoreUrl(const std::string& location) {
  return startsWith(location, "http://") || startsWith(location, "https://");
}

std::string unsafeTileName(const std::string& name) {
  if (name.empty()) return "an empty name";
  if (name.size() > 255) return "longer than 255 bytes";
  if (name == "." || name == ".." || name.find("..") != std::string::npos) return "it holds '..'";
  if (name.front() == '.') return "it starts with '.'";
  for (const char c : name) {
    if (c == '/' || c == '\\') return "it holds a path separator";
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) return "it holds a control character";
    if (c == '%' || c == '?' || c == '#') return "it holds '%', '?' or '#'";
  }
  return "";
}

std::string MapStoreConfig::validate() const {
  if (!(cache_max_bytes > 0)) return "map_store/cache_max_bytes must be > 0";
  if (!(connect_timeout > 0.0 && std::isfinite(connect_timeout))) return "map_store/connect_timeout must be > 0 s";
  if (!(transfer_timeout > 0.0 && std::isfinite(transfer_timeout))) return "map_store/transfer_timeout must be > 0 s";
  if (max_retries < 0 || max_retries > 20) return "map_store/max_retries must be in [0, 20]";
  if (!(retry_backoff >= 0.0 && retry_backoff <= 60.0)) return "map_store/retry_backoff must be in [0, 60] s";
  if (max_connections < 1 || max_connections > 64) return "map_store/max_connections must be in [1, 64]";
  if (max_tile_bytes == 0) return "map_store/max_tile_bytes must be > 0";
  if (max_index_bytes == 0) return "map_store/max_index_bytes must be > 0";
  if (!(poll_period > 0.0 && std::isfinite(poll_period))) return "map_store/poll_period must be > 0 s";
  return "";
}

MapStore::MapStore(const std::string& url, MapStoreConfig config) : backend_(mapStoreOpener()(url, config)) {}
MapStore::~MapStore() = default;

bool MapStore::pollIndex() { return backend_->pollIndex(); }
std::vector<FetchedTile> MapStore::fetch(const std::vector<std::string>& ids) { return backend_->fetch(ids); }
const std::string& MapStore::url() const { return backend_->url(); }
const TileIndexListing& MapStore::index() const { return backend_->index(); }
std::string MapStore::indexPath() const { return backend_->indexPath(); }
std::string MapStore::cacheDirectory() const { return backend_->cacheDirectory(); }
MapStoreStatus MapStore::status() const { return backend_->status(); }

}  // namespace grid_puzzle_localization
