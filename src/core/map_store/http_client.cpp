#include "http_client.hpp"

#include <curl/curl.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <mutex>
#include <sstream>
#include <stdexcept>

namespace grid_puzzle_localization {
namespace map_store_detail {
namespace {

void initCurlOnce() {
  static std::once_flag once;
  std::call_once(once, [] {
    if (curl_global_init(CURL_GLOBAL_DEFAULT) != CURLE_OK)
      throw std::runtime_error("map store: libcurl failed to initialise");
  });
}

// The first line of a credentials file, without trailing white space.
std::string readSecret(const std::string& path, const std::string& what) {
  std::ifstream in(path);
  std::string line;
  if (!in || !std::getline(in, line))
    throw std::invalid_argument("map_store/" + what + " " + path + " cannot be read or is empty");
  while (!line.empty() && std::isspace(static_cast<unsigned char>(line.back()))) line.pop_back();
  if (line.empty()) throw std::invalid_argument("map_store/" + what + " " + path + " is empty");
  return line;
}

struct Transfer {
  HttpResult* result = nullptr;
  std::uint64_t max_bytes = 0;
  curl_slist* headers = nullptr;
  char error[CURL_ERROR_SIZE] = {};
  bool http10 = false;     // the status line says HTTP/1.0
  std::string connection;  // the Connection header's tokens, lower case
};

std::size_t onBody(char* data, std::size_t size, std::size_t count, void* user) {
  auto* t = static_cast<Transfer*>(user);
  const std::size_t n = size * count;
  t->result->reached = true;
  if (t->result->body.size() + n > t->max_bytes) {
    t->result->too_large = true;
    return 0;  // aborts the transfer: nothing beyond the limit is kept
  }
  t->result->body.append(data, n);
  return n;
}

// `line` without its leading and trailing white space, lower case.
std::string trimmedLower(const std::string& line) {
  const auto first = line.find_first_not_of(" \t");
  const auto last = line.find_last_not_of(" \t\r\n");
  std::string out = first == std::string::npos ? "" : line.substr(first, last - first + 1);
  std::transform(out.begin(), out.end(), out.begin(), [](unsigned char c) { return std::tolower(c); });
  return out;
}

std::size_t onHeader(char* data, std::size_t size, std::size_t count, void* user) {
  auto* t = static_cast<Transfer*>(user);
  const std::size_t n = size * count;
  t->result->reached = true;
  const std::string line(data, n);
  const std::string lower = trimmedLower(line);
  if (lower.rfind("http/", 0) == 0) {  // a status line (a new header block)
    t->http10 = lower.rfind("http/1.0", 0) == 0;
    t->connection.clear();
  } else if (lower.rfind("connection:", 0) == 0) {
    t->connection = trimmedLower(lower.substr(11));
  } else if (lower.rfind("etag:", 0) == 0) {
    const std::string value = line.substr(line.find(':') + 1);  // ETags are case-sensitive
    const auto first = value.find_first_not_of(" \t");
    const auto last = value.find_last_not_of(" \t\r\n");
    t->result->etag = first == std::string::npos ? "" : value.substr(first, last - first + 1);
  }
  return n;
}

}  // namespace

HttpClient::HttpClient(const MapStoreConfig& config) : config_(config) {
  initCurlOnce();
  if (!config.bearer_token_file.empty()) bearer_ = readSecret(config.bearer_token_file, "bearer_token_file");
  if (bearer_.empty() && !config.bearer_token_env.empty()) {
    const char* value = std::getenv(config.bearer_token_env.c_str());
    if (value == nullptr || *value == '\0')
      throw std::invalid_argument("map_store/bearer_token_env names " + config.bearer_token_env +
                                  ", which is not set or empty");
    bearer_ = value;
  }
  if (!config.basic_auth_file.empty()) {
    basic_ = readSecret(config.basic_auth_file, "basic_auth_file");
    if (basic_.find(':') == std::string::npos)
      throw std::invalid_argument("map_store/basic_auth_file " + config.basic_auth_file +
                                  " must hold user:password on its first line");
  }
  CURLM* multi = curl_multi_init();
  if (multi == nullptr) throw std::runtime_error("map store: curl_multi_init failed");
  curl_multi_setopt(multi, CURLMOPT_MAXCONNECTS, static_cast<long>(std::max(1, config.max_connections)));
  multi_ = multi;
  limitParallelRequests(config.max_connections);
}

void HttpClient::limitParallelRequests(int requests) {
  parallel_ = std::max(1, requests);
  // Each transfer holds a connection, so the connection limits are the limit of transfers run at once; the others
  // wait in the multi's queue, in the order they were added.
  CURLM* multi = static_cast<CURLM*>(multi_);
  curl_multi_setopt(multi, CURLMOPT_MAX_TOTAL_CONNECTIONS, static_cast<long>(parallel_));
  curl_multi_setopt(multi, CURLMOPT_MAX_HOST_CONNECTIONS, static_cast<long>(parallel_));
}

void HttpClient::adaptTo(const std::vector<HttpResult>& results) {
  bool answered = false, closes = false;
  for (const HttpResult& r : results) {
    if (r.status == 0) continue;  // no answer: says nothing about the server's connections
    answered = true;
    closes = closes || !r.keeps_alive;
  }
  if (answered)
    limitParallelRequests(closes ? std::min(config_.max_connections, kClosingServerConnections)
                                 : config_.max_connections);
}

HttpClient::~HttpClient() { curl_multi_cleanup(static_cast<CURLM*>(multi_)); }

std::vector<HttpResult> HttpClient::get(const std::vector<HttpGet>& requests) {
  CURLM* multi = static_cast<CURLM*>(multi_);
  std::vector<HttpResult> results(requests.size());
  std::vector<std::unique_ptr<Transfer>> transfers;
  std::vector<CURL*> handles;
  for (std::size_t k = 0; k < requests.size(); ++k) {
    const HttpGet& req = requests[k];
    auto t = std::make_unique<Transfer>();
    t->result = &results[k];
    t->max_bytes = req.max_bytes;
    CURL* h = curl_easy_init();
    if (h == nullptr) throw std::runtime_error("map store: curl_easy_init failed");
    curl_easy_setopt(h, CURLOPT_URL, req.url.c_str());
    curl_easy_setopt(h, CURLOPT_PRIVATE, t.get());
    curl_easy_setopt(h, CURLOPT_ERRORBUFFER, t->error);
    curl_easy_setopt(h, CURLOPT_WRITEFUNCTION, onBody);
    curl_easy_setopt(h, CURLOPT_WRITEDATA, t.get());
    curl_easy_setopt(h, CURLOPT_HEADERFUNCTION, onHeader);
    curl_easy_setopt(h, CURLOPT_HEADERDATA, t.get());
    curl_easy_setopt(h, CURLOPT_NOSIGNAL, 1L);
    curl_easy_setopt(h, CURLOPT_CONNECTTIMEOUT_MS, static_cast<long>(config_.connect_timeout * 1000.0));
    curl_easy_setopt(h, CURLOPT_TIMEOUT_MS, static_cast<long>(config_.transfer_timeout * 1000.0));
    curl_easy_setopt(h, CURLOPT_TCP_KEEPALIVE, 1L);
    curl_easy_setopt(h, CURLOPT_MAXFILESIZE_LARGE, static_cast<curl_off_t>(req.max_bytes));
    curl_easy_setopt(h, CURLOPT_FOLLOWLOCATION, 0L);  // credentials never follow a redirect elsewhere
#if LIBCURL_VERSION_NUM >= 0x075500
    curl_easy_setopt(h, CURLOPT_PROTOCOLS_STR, "http,https");
#else
    curl_easy_setopt(h, CURLOPT_PROTOCOLS, static_cast<long>(CURLPROTO_HTTP | CURLPROTO_HTTPS));
#endif
    curl_easy_setopt(h, CURLOPT_SSL_VERIFYPEER, 1L);
    curl_easy_setopt(h, CURLOPT_SSL_VERIFYHOST, 2L);
    if (!config_.ca_file.empty()) curl_easy_setopt(h, CURLOPT_CAINFO, config_.ca_file.c_str());
    curl_easy_setopt(h, CURLOPT_USERAGENT, "grid_puzzle_localization-map-store");
    if (!bearer_.empty()) {
      curl_easy_setopt(h, CURLOPT_HTTPAUTH, static_cast<long>(CURLAUTH_BEARER));
      curl_easy_setopt(h, CURLOPT_XOAUTH2_BEARER, bearer_.c_str());
    } else if (!basic_.empty()) {
      curl_easy_setopt(h, CURLOPT_HTTPAUTH, static_cast<long>(CURLAUTH_BASIC));
      curl_easy_setopt(h, CURLOPT_USERPWD, basic_.c_str());
    }
    if (!req.if_none_match.empty()) {
      t->headers = curl_slist_append(t->headers, ("If-None-Match: " + req.if_none_match).c_str());
      curl_easy_setopt(h, CURLOPT_HTTPHEADER, t->headers);
    }
    curl_multi_add_handle(multi, h);
    handles.push_back(h);
    transfers.push_back(std::move(t));
  }
  const auto finish = [&](CURL* h, CURLcode code) {
    Transfer* t = nullptr;
    curl_easy_getinfo(h, CURLINFO_PRIVATE, reinterpret_cast<char**>(&t));
    HttpResult& r = *t->result;
    long status = 0, connects = 0;
    curl_easy_getinfo(h, CURLINFO_RESPONSE_CODE, &status);
    curl_easy_getinfo(h, CURLINFO_NUM_CONNECTS, &connects);
    r.status = status;
    r.connects = connects;
    r.keeps_alive = t->http10 ? t->connection.find("keep-alive") != std::string::npos
                              : t->connection.find("close") == std::string::npos;
    if (status > 0) r.reached = true;
    if (code == CURLE_OK) {
      r.transferred = true;
    } else if (r.too_large || code == CURLE_FILESIZE_EXCEEDED) {
      r.too_large = true;
      r.error = "body larger than " + std::to_string(t->max_bytes) + " bytes";
    } else {
      r.error = std::string(curl_easy_strerror(code)) + (t->error[0] ? std::string(": ") + t->error : "");
    }
  };
  int running = 0;
  do {
    curl_multi_perform(multi, &running);
    int queued = 0;
    while (CURLMsg* m = curl_multi_info_read(multi, &queued))
      if (m->msg == CURLMSG_DONE) finish(m->easy_handle, m->data.result);
    if (running > 0) curl_multi_poll(multi, nullptr, 0, 100, nullptr);
  } while (running > 0);
  int queued = 0;
  while (CURLMsg* m = curl_multi_info_read(multi, &queued))
    if (m->msg == CURLMSG_DONE) finish(m->easy_handle, m->data.result);
  for (std::size_t k = 0; k < handles.size(); ++k) {
    curl_multi_remove_handle(multi, handles[k]);
    curl_easy_cleanup(handles[k]);
    curl_slist_free_all(transfers[k]->headers);
  }
  adaptTo(results);
  return results;
}

}  // namespace map_store_detail
}  // namespace grid_puzzle_localization
