// The map store's HTTP client (libcurl multi): concurrent GETs over kept-alive connections (fewer at once to a server
// that closes every connection: kClosingServerConnections), with connect and transfer timeouts, a body size limit
// enforced while receiving, TLS verified against the system CA store, and optional bearer or basic credentials (never
// logged). One attempt per request: the store retries. No ROS.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "grid_puzzle_localization/map_store/map_store.hpp"

namespace grid_puzzle_localization {
namespace map_store_detail {

struct HttpGet {
  std::string url;
  std::string if_none_match;    ///< an ETag; "" = unconditional
  std::uint64_t max_bytes = 0;  ///< a longer body is aborted while it arrives (too_large)
};

struct HttpResult {
  bool transferred = false;  ///< the request completed at the HTTP level (any status)
  long status = 0;           ///< HTTP status, 0 without an answer
  bool reached = false;      ///< the server answered (even partly); false: no connection, timeout before an answer
  bool too_large = false;    ///< the body passed max_bytes
  std::string body;
  std::string etag;
  std::string error;  ///< the transport error ("" when transferred)
  long connects = 0;  ///< new connections this request opened
  /// The answer left its connection open for the next request: HTTP/1.1 without "Connection: close", HTTP/1.0 only
  /// with "Connection: keep-alive".
  bool keeps_alive = true;
};

class HttpClient {
 public:
  /// Reads the credentials the config names; throws std::invalid_argument naming the file or variable.
  explicit HttpClient(const MapStoreConfig& config);
  ~HttpClient();
  HttpClient(const HttpClient&) = delete;
  HttpClient& operator=(const HttpClient&) = delete;

  /// Runs `requests` concurrently (at most parallelRequests() at a time) and returns their results in order.
  std::vector<HttpResult> get(const std::vector<HttpGet>& requests);
  /// max_connections, or at most kClosingServerConnections once the server's last answers closed their
  /// connections (a new connection per request); back to max_connections when it keeps them alive again.
  int parallelRequests() const { return parallel_; }

 private:
  MapStoreConfig config_;
  std::string bearer_, basic_;  // credentials: never logged or put in a message
  void* multi_ = nullptr;       // CURLM*, whose connection cache keeps connections alive between calls
  int parallel_ = 0;            // requests run at once (the multi's connection limits)
  void limitParallelRequests(int requests);
  void adaptTo(const std::vector<HttpResult>& results);
};

}  // namespace map_store_detail
}  // namespace grid_puzzle_localization
