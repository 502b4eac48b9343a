// A tiled map served over HTTP(S): the layout `gpm tile` writes (index.json + <cx>_<cy>.pcd) under a URL prefix, as
// any static server, CDN or bucket serves it. The store fetches index.json (conditional GET with ETag), fetches tiles
// concurrently over kept-alive connections with timeouts and bounded retries, checks every tile against the index
// (size, SHA-256) before it is stored or used, and keeps them in a bounded LRU disk cache (atomic writes, kept across
// restarts). Tiles are then read from the cache like a local tile directory. No ROS. See docs/map_store.md.
// The store's work (libcurl, OpenSSL) lives in a library of its own that the first MapStore loads: a localizer on a
// local map never maps libcurl's TLS stack, about 5 MiB of resident memory.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "grid_puzzle_localization/provider/tile_directory.hpp"

namespace grid_puzzle_localization {
namespace map_store_detail {
class Backend;
}  // namespace map_store_detail

/// The map store's settings; the parameter names are the field names under `map_store/`.
struct MapStoreConfig {
  std::string cache_dir;  ///< "" = $XDG_CACHE_HOME (else ~/.cache)/grid_puzzle_localization/map_store
  std::uint64_t cache_max_bytes = 1ull << 30;   ///< tile bytes kept on disk per map URL [bytes] (1 GiB)
  double connect_timeout = 5.0;                 ///< [s] to open a connection
  double transfer_timeout = 30.0;               ///< [s] for one whole request (connection included)
  int max_retries = 3;                          ///< further attempts after a failed one (timeouts, 5xx, bad bytes)
  double retry_backoff = 0.5;                   ///< [s] pause before the first retry, doubled for each next one
  int max_connections = 16;                     ///< concurrent fetches (and kept-alive connections)
  std::uint64_t max_tile_bytes = 256ull << 20;  ///< a tile larger than this is refused before it is stored [bytes]
  std::uint64_t max_index_bytes = 1ull << 30;   ///< index.json larger than this is refused [bytes]
  std::string ca_file;                          ///< "" = the system CA store (HTTPS is always verified)
  std::string bearer_token_file;                ///< file holding a bearer token (Authorization: Bearer), "" = none
  std::string bearer_token_env;                 ///< name of an environment variable holding a bearer token, "" = none
  std::string basic_auth_file;                  ///< file holding "user:password" for HTTP basic auth, "" = none
  double poll_period = 5.0;                     ///< [s] between polls of index.json for a new revision (the provider)

  /// "" when valid, else what is wrong, naming the field.
  std::string validate() const;
};

/// Tiles the map worker asks of fetch() at once, then reads before it asks for more: several rounds of
/// max_connections requests, so a link's round trips overlap.
constexpr std::size_t kTileFetchBatch = 64;

/// Requests run at once against a server that closes the connection after every answer (HTTP/1.0 such as `python3
/// -m http.server`, or "Connection: close"). Each of its requests opens a connection, and a burst of connections
/// overflows a small accept queue: Python's socketserver listens with a backlog of 5, and every connection the
/// kernel drops waits out TCP's 1 s SYN retransmission, holding up its whole fetch batch (64 tiles/s from a server
/// that answers 1,500 tiles/s one at a time). Four never overflow a backlog of 5, and still overlap round trips.
constexpr int kClosingServerConnections = 4;

/// What the store did, and whether its server answers.
struct MapStoreStatus {
  std::string url;                  ///< the map's URL (never with credentials)
  bool reachable = true;            ///< the last request reached the server (any HTTP answer)
  std::string last_error;           ///< the last failure, naming the URL; "" if none yet
  std::string revision;             ///< of the index in use: "sha256:" + the first 16 hex digits of its bytes' SHA-256
  std::size_t tiles_fetched = 0;    ///< tiles downloaded and stored
  std::size_t cache_hits = 0;       ///< tiles served from the disk cache
  std::size_t failed_attempts = 0;  ///< requests that failed (each retry counts)
  std::size_t connections_opened = 0;  ///< new connections (keep-alive reuses them)
  int parallel_requests = 0;        ///< requests run at once now: max_connections, or at most kClosingServerConnections
                                    ///< while the server closes its connection after every answer
  std::uint64_t bytes_fetched = 0;  ///< tile bytes downloaded
  std::uint64_t cache_bytes = 0;    ///< tile bytes in the disk cache now
};

/// One tile asked of fetch(): the path of its checked copy in the cache, or why there is none.
struct FetchedTile {
  std::string id;     ///< the stem asked for, e.g. "1.0_-3.0"
  std::string path;   ///< cached file, checked against the index; "" on failure
  std::string error;  ///< names the tile's URL and what failed; "" on success
};

/// Lowercase hex SHA-256 of `bytes` (OpenSSL EVP): the checksum index.json gives each tile. Defined in the map store's
/// own library (lib<package>_map_store, link it to call this), not in the core.
std::string sha256Hex(const std::string& bytes);

/// True for "http://..." and "https://...": where a tile directory is accepted, such a string names a map store.
bool isMapStoreUrl(const std::string& location);

/// A tile name from an index or a delta that is safe to append to the URL and the cache directory: no '/', '\\',
/// "..", leading '.', control characters or '%', at most 255 bytes. "" when safe, else why not.
std::string unsafeTileName(const std::string& name);

class MapStore {
 public:
  /// Opens the map at `url` (http(s)://host[:port]/prefix; no credentials, query or fragment in it) and fetches its
  /// index. When the server cannot be reached but the cache holds an index of this URL, the store starts offline on
  /// what the cache holds (status().reachable false). Throws std::invalid_argument naming the URL and what failed
  /// (bad URL or config, unreachable server with an empty cache, a bad index).
  MapStore(const std::string& url, MapStoreConfig config = {});
  ~MapStore();
  MapStore(const MapStore&) = delete;
  MapStore& operator=(const MapStore&) = delete;

  /// Asks the server for index.json again (If-None-Match with the last ETag). True when a new revision is now in
  /// use (its tiles are checked against it from now on); false when unchanged or unreachable (status() says why;
  /// the index held stays in use).
  bool pollIndex();

  /// The checked cached copies of tiles `ids` (file stems), fetching the missing ones concurrently. Tiles not in
  /// the index, with unsafe names, larger than the index says or than max_tile_bytes, or whose bytes do not match
  /// the index are refused; each failure is reported in its FetchedTile. Blocks (network): never call it from a
  /// thread that must not wait. The files returned stay in the cache until the next call.
  std::vector<FetchedTile> fetch(const std::vector<std::string>& ids);

  const std::string& url() const;
  /// The index in use (its tiles and their checksums).
  const TileIndexListing& index() const;
  /// The cached index.json of the revision in use (a local file, e.g. for openTileDirectory on its directory).
  std::string indexPath() const;
  /// The cache directory of this URL.
  std::string cacheDirectory() const;
  MapStoreStatus status() const;

 private:
  std::unique_ptr<map_store_detail::Backend> backend_;
};

}  // namespace grid_puzzle_localization
