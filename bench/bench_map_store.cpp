// make bench-map-store: the map store fetching a window of tiles from a real nginx on localhost
// (test/cpp/nginx_server.hpp), and the 8 KiB tiles from `python3 -m http.server` too, as the map worker does (batches
// of kTileFetchBatch): cold (every tile downloaded, checked and stored), warm (every tile from the disk cache, checked
// again) and an index poll answered 304. One JSON line per configuration (tile size, connections). Localhost has no
// network latency: the figures are the client's own cost (HTTP, SHA-256, disk cache), the floor of what a remote server
// adds to. Medians of 3 runs, each on a fresh cache.
// --quick: tiny, one run, for `make test`.
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "grid_puzzle_localization/map_store/map_store.hpp"
#include "grid_puzzle_localization/provider/tile_directory.hpp"
#include "nginx_server.hpp"
#include "python_http_server.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

std::string makeTempDir() {
  const char* base = std::getenv("TMPDIR");
  std::string tmpl = std::string(base && *base ? base : "/tmp") + "/gpl_bench_map_store_XXXXXX";
  if (::mkdtemp(&tmpl[0]) == nullptr) throw std::runtime_error("mkdtemp failed");
  return tmpl;
}

// `count` tiles of `bytes` random bytes each and their index.json under root/map; the stems.
std::vector<std::string> writeMap(const std::string& root, int count, std::size_t bytes) {
  ::mkdir((root + "/map").c_str(), 0755);
  std::mt19937_64 rng(7);
  std::vector<std::string> ids;
  std::string entries;
  for (int k = 0; k < count; ++k) {
    const std::string id = gpl::tileStem(k % 100, k / 100, 2.0);
    std::string data(bytes, '\0');
    for (std::size_t b = 0; b + 8 <= bytes; b += 8) {
      const std::uint64_t v = rng();
      std::memcpy(&data[b], &v, 8);
    }
    std::ofstream(root + "/map/" + id + ".pcd", std::ios::binary) << data;
    entries += std::string(entries.empty() ? "" : ",") + R"({"key":[)" + std::to_string(k % 100) + "," +
               std::to_string(k / 100) + R"(],"file":")" + id + R"(.pcd","bytes":)" + std::to_string(bytes) +
               R"(,"sha256":")" + gpl::sha256Hex(data) + "\"}";
    ids.push_back(id);
  }
  std::ofstream(root + "/map/index.json")
      << R"({"format":"grid_puzzle_tiles","version":1,"grid_size":2.0,"tiles":[)" << entries << "]}";
  return ids;
}

double fetchAll(gpl::MapStore& store, const std::vector<std::string>& ids) {
  const auto start = Clock::now();
  for (std::size_t k = 0; k < ids.size(); k += gpl::kTileFetchBatch) {
    const std::vector<std::string> batch(ids.begin() + k, ids.begin() + std::min(ids.size(), k + gpl::kTileFetchBatch));
    for (const gpl::FetchedTile& t : store.fetch(batch))
      if (t.path.empty()) throw std::runtime_error(t.error);
  }
  return secondsSince(start);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

std::string cpuModel() {
  std::ifstream in("/proc/cpuinfo");
  for (std::string line; std::getline(in, line);)
    if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
  return "unknown";
}

// Fetches `ids` from `url` cold and warm, polls the index, `runs` times on a fresh cache each; prints one JSON line.
void benchStore(const std::string& server, const std::string& url, const std::vector<std::string>& ids,
                std::size_t bytes, int connections, int runs, int polls) {
  std::vector<double> colds, warms, polls_ms;
  gpl::MapStoreStatus s;
  for (int run = 0; run < runs; ++run) {
    const std::string cache = makeTempDir();
    gpl::MapStoreConfig config;
    config.cache_dir = cache;
    config.max_connections = connections;
    gpl::MapStore store(url, config);
    colds.push_back(fetchAll(store, ids));
    warms.push_back(fetchAll(store, ids));
    const auto start = Clock::now();
    for (int p = 0; p < polls; ++p) store.pollIndex();
    polls_ms.push_back(secondsSince(start) / polls * 1e3);
    s = store.status();
    std::system(("rm -rf '" + cache + "'").c_str());
  }
  const double cold = median(colds), warm = median(warms);
  const int count = static_cast<int>(ids.size());
  double load[1] = {0.0};
  getloadavg(load, 1);
  std::printf(
      "{\"bench\":\"map_store\",\"server\":\"%s\",\"tile_bytes\":%zu,\"tiles\":%d,\"max_connections\":%d,"
      "\"parallel_requests\":%d,\"runs\":%zu,\"cold_s\":%.4f,\"cold_tiles_per_s\":%.1f,\"cold_mb_per_s\":%.1f,"
      "\"warm_s\":%.4f,\"warm_tiles_per_s\":%.1f,\"index_poll_304_ms\":%.3f,\"connections_opened\":%zu,"
      "\"cpu\":\"%s\",\"cores\":%u,\"load_average\":%.2f}\n",
      server.c_str(), bytes, count, connections, s.parallel_requests, colds.size(), cold, count / cold,
      count * bytes / cold / 1e6, warm, count / warm, median(polls_ms), s.connections_opened, cpuModel().c_str(),
      std::thread::hardware_concurrency(), load[0]);
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  if (gpl_test::NginxServer::binary().empty()) {
    std::fprintf(stderr, "bench_map_store: nginx is not installed (apt-get install nginx-light)\n");
    return 2;
  }
  const int count = quick ? 40 : 1000;
  const int runs = quick ? 1 : 3, polls = quick ? 5 : 50;
  const int default_connections = gpl::MapStoreConfig().max_connections;
  const std::vector<std::size_t> sizes =
      quick ? std::vector<std::size_t>{8192} : std::vector<std::size_t>{8192, 262144};
  for (const std::size_t bytes : sizes) {
    const std::string root = makeTempDir();
    const std::vector<std::string> ids = writeMap(root, count, bytes);
    {
      gpl_test::NginxServer server(root);
      server.start();
      for (const int connections : {1, default_connections})  // one, and the default
        benchStore("nginx", server.url("/map"), ids, bytes, connections, runs, polls);
    }
    // The plain static server a new user tries first: HTTP/1.0, a new connection per request (issue 58).
    if (bytes == sizes.front()) {
      gpl_test::PythonHttpServer server(root);
      for (const int connections : {1, default_connections})
        benchStore("python_http_server", server.url("/map"), ids, bytes, connections, runs, polls);
    }
    std::system(("rm -rf '" + root + "'").c_str());
  }
  return 0;
}
