// The map store against a real nginx (test/cpp/nginx_server.hpp) on a free localhost port: tiles fetched
// concurrently over kept-alive connections and checked against the index, and each way a server or its files can
// fail: 404 for one tile, a truncated or corrupt file, a file larger than the index says, a slow server, a server
// down at start and in the middle, a new revision, a hostile index, the cache's byte budget and a restart.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <random>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "grid_puzzle_localization/localizer.hpp"
#include "grid_puzzle_localization/map_store/map_store.hpp"
#include "grid_puzzle_localization/map_update_worker.hpp"
#include "grid_puzzle_localization/provider/tile_directory.hpp"
#include "grid_puzzle_localization/provider/tile_references.hpp"
#include "nginx_server.hpp"
#include "python_http_server.hpp"
#include "synthetic_world.hpp"
#include "tile_files.hpp"

namespace gpl = grid_puzzle_localization;
using gpl_test::NginxServer;

namespace {

std::string makeTempDir() {
  char tmpl[] = "/tmp/gpl_map_store_XXXXXX";
  if (::mkdtemp(tmpl) == nullptr) throw std::runtime_error("mkdtemp failed");
  return tmpl;
}

void writeFile(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out << bytes;
}

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// A served map: `count` tiles of side 2 m in one row with random bytes (the store does not parse them), and its
// index.json with sizes and checksums.
class ServedMap {
 public:
  explicit ServedMap(int count, std::size_t bytes = 2000, std::uint32_t seed = 1) : root_(makeTempDir()) {
    ::mkdir((root_ + "/map").c_str(), 0755);
    std::mt19937 rng(seed);
    for (int i = 0; i < count; ++i) {
      std::string data(bytes + static_cast<std::size_t>(i), '\0');
      for (char& c : data) c = static_cast<char>(rng());
      tiles_[gpl::tileStem(i, 0, 2.0)] = data;
    }
    writeAll();
  }
  ~ServedMap() { std::system(("rm -rf '" + root_ + "'").c_str()); }

  const std::string& root() const { return root_; }
  std::string path(const std::string& id) const { return root_ + "/map/" + id + ".pcd"; }
  std::vector<std::string> ids() const {
    std::vector<std::string> out;
    for (const auto& [id, data] : tiles_) out.push_back(id);
    return out;
  }
  const std::string& bytes(const std::string& id) const { return tiles_.at(id); }
  void set(const std::string& id, const std::string& data) { tiles_[id] = data; }
  /// Writes every tile and the index (the index last, by rename, as `gpm tile` replaces a directory).
  void writeAll(bool checksums = true) {
    std::string entries;
    int i = 0;
    for (const auto& [id, data] : tiles_) {
      writeFile(path(id), data);
      if (!entries.empty()) entries += ",";
      entries += R"({"key":[)" + std::to_string(i++) + R"(,0],"file":")" + id + R"(.pcd","bytes":)" +
                 std::to_string(data.size()) + (checksums ? R"(,"sha256":")" + gpl::sha256Hex(data) + "\"" : "") + "}";
    }
    writeIndex(entries);
  }
  void writeIndex(const std::string& entries) {
    writeFile(root_ + "/map/index.json.tmp",
              R"({"format":"grid_puzzle_tiles","version":1,"grid_size":2.0,"tiles":[)" + entries + "]}");
    std::rename((root_ + "/map/index.json.tmp").c_str(), (root_ + "/map/index.json").c_str());
  }

 private:
  std::string root_;
  std::map<std::string, std::string> tiles_;
};

class MapStoreTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (NginxServer::binary().empty())
      GTEST_SKIP() << "nginx is not installed (apt-get install nginx-light; tools/apt-packages.txt lists it)";
    map_ = std::make_unique<ServedMap>(8);
    // /slow/: the index at full speed, the tiles at 1 kB/s.
    server_ = std::make_unique<NginxServer>(map_->root(), "    location /slow/ { alias " + map_->root() +
                                                              "/map/; }\n    location ~ ^/slow/(.+\\.pcd)$ { alias " +
                                                              map_->root() +
                                                              "/map/$1; limit_rate 1k; }\n"
                                                              "    location /auth/ { alias " +
                                                              map_->root() +
                                                              "/map/; if ($http_authorization != \"Bearer s3cret\") "
                                                              "{ return 401; } }\n");
    server_->start();
    cache_ = makeTempDir();
    config_.cache_dir = cache_;
    config_.retry_backoff = 0.01;
    config_.connect_timeout = 1.0;
    config_.transfer_timeout = 5.0;
    config_.max_connections = 2;
  }
  void TearDown() override {
    if (!cache_.empty()) std::system(("rm -rf '" + cache_ + "'").c_str());
  }

  std::string url() const { return server_->url("/map"); }

  std::unique_ptr<ServedMap> map_;
  std::unique_ptr<NginxServer> server_;
  std::string cache_;
  gpl::MapStoreConfig config_;
};

std::uint64_t directoryBytes(const std::string& dir) {
  std::uint64_t total = 0;
  FILE* p = ::popen(("find '" + dir + "' -type f -printf '%s\\n'").c_str(), "r");
  char line[64];
  while (std::fgets(line, sizeof(line), p)) total += std::strtoull(line, nullptr, 10);
  ::pclose(p);
  return total;
}

}  // namespace

TEST_F(MapStoreTest, FetchesEveryTileConcurrentlyOverKeptAliveConnections) {
  gpl::MapStore store(url() + "/", config_);  // a trailing slash is dropped
  EXPECT_EQ(store.url(), url());
  EXPECT_EQ(store.index().tiles.size(), 8u);
  const auto fetched = store.fetch(map_->ids());
  ASSERT_EQ(fetched.size(), 8u);
  for (const gpl::FetchedTile& t : fetched) {
    ASSERT_EQ(t.error, "") << t.id;
    EXPECT_TRUE(readFile(t.path) == map_->bytes(t.id)) << t.id;
  }
  gpl::MapStoreStatus status = store.status();
  EXPECT_TRUE(status.reachable);
  EXPECT_EQ(status.tiles_fetched, 8u);
  // Index and eight tiles over at most max_connections connections.
  EXPECT_LE(status.connections_opened, 2u);
  EXPECT_GE(status.connections_opened, 1u);
  // Asked again: from the cache, nothing fetched.
  for (const gpl::FetchedTile& t : store.fetch(map_->ids())) EXPECT_EQ(t.error, "");
  status = store.status();
  EXPECT_EQ(status.tiles_fetched, 8u);
  EXPECT_EQ(status.cache_hits, 8u);
  EXPECT_EQ(status.revision.substr(0, 7), "sha256:");
}

// A server that closes the connection after every answer gets at most kClosingServerConnections requests at once:
// a burst of new connections would overflow its accept queue (python3 -m http.server: a backlog of 5), and each
// connection the kernel drops waits out a 1 s SYN retransmission (issue 58: 64 tiles/s from a server that serves
// 1,500 one at a time). Asserted on the mechanism, not on time; bench_map_store measures the rate.
TEST_F(MapStoreTest, AServerThatClosesEveryConnectionGetsFewRequestsAtOnce) {
  config_.max_connections = gpl::MapStoreConfig().max_connections;
  ASSERT_GT(config_.max_connections, gpl::kClosingServerConnections);
  {  // HTTP/1.0, no keep-alive
    gpl_test::PythonHttpServer python(map_->root());
    gpl::MapStore store(python.url("/map"), config_);
    EXPECT_EQ(store.status().parallel_requests, gpl::kClosingServerConnections);
    for (const gpl::FetchedTile& t : store.fetch(map_->ids())) EXPECT_EQ(t.error, "") << t.id;
    EXPECT_EQ(store.status().connections_opened, 1 + map_->ids().size());  // one per request: none kept
    EXPECT_EQ(store.status().parallel_requests, gpl::kClosingServerConnections);
  }
  {  // HTTP/1.1 with "Connection: close"
    NginxServer closing(map_->root(), "    keepalive_timeout 0;\n");
    closing.start();
    config_.cache_dir = makeTempDir();
    gpl::MapStore store(closing.url("/map"), config_);
    EXPECT_EQ(store.status().parallel_requests, gpl::kClosingServerConnections);
    std::system(("rm -rf '" + config_.cache_dir + "'").c_str());
  }
  // A server that keeps its connections alive gets max_connections.
  config_.cache_dir = cache_;
  config_.cache_dir += "/kept";
  gpl::MapStore kept(url(), config_);
  EXPECT_EQ(kept.status().parallel_requests, config_.max_connections);
}

TEST_F(MapStoreTest, OneMissingTruncatedCorruptOrOversizedTileIsRefusedAndTheRestServed) {
  gpl::MapStore store(url(), config_);
  const std::vector<std::string> ids = map_->ids();
  std::remove(map_->path(ids[0]).c_str());                            // 404
  writeFile(map_->path(ids[1]), map_->bytes(ids[1]).substr(0, 500));  // truncated on the server
  std::string corrupt = map_->bytes(ids[2]);
  corrupt[100] ^= 0x40;
  writeFile(map_->path(ids[2]), corrupt);                                       // same size, other bytes
  writeFile(map_->path(ids[3]), map_->bytes(ids[3]) + std::string(5000, 'x'));  // larger than the index says
  const auto fetched = store.fetch(ids);
  const auto expectError = [&](std::size_t k, const std::string& what) {
    EXPECT_EQ(fetched[k].path, "");
    EXPECT_NE(fetched[k].error.find(url() + "/" + ids[k] + ".pcd"), std::string::npos) << fetched[k].error;
    EXPECT_NE(fetched[k].error.find(what), std::string::npos) << fetched[k].error;
  };
  expectError(0, "HTTP 404");
  expectError(1, "truncated");
  expectError(2, "SHA-256 does not match");
  expectError(3, "refused before it was stored");
  for (std::size_t k = 4; k < ids.size(); ++k) EXPECT_TRUE(readFile(fetched[k].path) == map_->bytes(ids[k]));
  // Nothing of the four bad tiles reached the cache.
  EXPECT_EQ(directoryBytes(store.cacheDirectory() + "/tiles"), store.status().cache_bytes);
  std::uint64_t good = 0;
  for (std::size_t k = 4; k < ids.size(); ++k) good += map_->bytes(ids[k]).size();
  EXPECT_EQ(store.status().cache_bytes, good);
  EXPECT_TRUE(store.status().reachable);
  EXPECT_NE(store.status().last_error, "");
}

TEST_F(MapStoreTest, ASlowServerTimesOutWithinTheTransferTimeout) {
  config_.transfer_timeout = 0.3;
  config_.max_retries = 1;
  gpl::MapStore store(server_->url("/slow"), config_);
  const auto start = std::chrono::steady_clock::now();
  const auto fetched = store.fetch({map_->ids()[0]});  // 2000 bytes at 1 kB/s: 2 s
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_EQ(fetched[0].path, "");
  EXPECT_NE(fetched[0].error.find("imeout"), std::string::npos) << fetched[0].error;
  EXPECT_LT(seconds, 1.5);  // two attempts of 0.3 s, not the 2 s the transfer needs
}

TEST_F(MapStoreTest, ServerDownAtStartWithAnEmptyCacheStopsNamingTheUrl) {
  server_->stop();
  try {
    gpl::MapStore store(url(), config_);
    FAIL() << "opened a store whose server is down";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(url() + "/index.json"), std::string::npos) << what;
    EXPECT_NE(what.find("onnect"), std::string::npos) << what;  // "Couldn't connect to server"
    EXPECT_NE(what.find("holds no index"), std::string::npos) << what;
  }
}

TEST_F(MapStoreTest, ServerDownInTheMiddleKeepsServingTheCacheAndRecovers) {
  gpl::MapStore store(url(), config_);
  const std::vector<std::string> ids = map_->ids();
  ASSERT_EQ(store.fetch({ids[0], ids[1]})[1].error, "");
  server_->stop();
  const auto offline = store.fetch({ids[0], ids[2]});
  EXPECT_TRUE(readFile(offline[0].path) == map_->bytes(ids[0]));  // held: still served
  EXPECT_EQ(offline[1].path, "");
  EXPECT_NE(offline[1].error.find(url() + "/" + ids[2] + ".pcd"), std::string::npos) << offline[1].error;
  gpl::MapStoreStatus status = store.status();
  EXPECT_FALSE(status.reachable);
  EXPECT_EQ(status.url, url());
  EXPECT_NE(status.last_error.find(url()), std::string::npos) << status.last_error;
  EXPECT_FALSE(store.pollIndex());  // unreachable: the index held stays in use
  server_->start();
  const auto back = store.fetch({ids[2]});
  EXPECT_TRUE(readFile(back[0].path) == map_->bytes(ids[2]));
  EXPECT_TRUE(store.status().reachable);
}

TEST_F(MapStoreTest, ANewRevisionIsPolledWithTheETagAndOnlyChangedTilesAreFetchedAgain) {
  gpl::MapStore store(url(), config_);
  const std::vector<std::string> ids = map_->ids();
  store.fetch(ids);
  const std::string first = store.status().revision;
  EXPECT_FALSE(store.pollIndex());  // 304 Not Modified
  EXPECT_EQ(store.status().revision, first);
  // nginx's ETag is the file's modification time in seconds and its size: an index rewritten within the same second
  // at the same size keeps its ETag (docs/map_store.md). This one changes size.
  map_->set(ids[3], std::string(150, 'n'));
  map_->writeAll();
  EXPECT_TRUE(store.pollIndex());
  EXPECT_NE(store.status().revision, first);
  const std::size_t before = store.status().tiles_fetched;
  const auto fetched = store.fetch(ids);
  for (std::size_t k = 0; k < ids.size(); ++k) EXPECT_TRUE(readFile(fetched[k].path) == map_->bytes(ids[k]));
  EXPECT_EQ(store.status().tiles_fetched, before + 1);  // only the changed tile
}

TEST_F(MapStoreTest, TheCacheHoldsItsByteBudgetLeastRecentlyUsedOut) {
  config_.cache_max_bytes = 3 * 2010;  // three tiles
  gpl::MapStore store(url(), config_);
  const std::vector<std::string> ids = map_->ids();
  for (std::size_t k = 0; k + 1 < ids.size(); k += 2) {
    for (const auto& t : store.fetch({ids[k], ids[k + 1]})) EXPECT_EQ(t.error, "");
    EXPECT_LE(store.status().cache_bytes, config_.cache_max_bytes);
    EXPECT_EQ(directoryBytes(store.cacheDirectory() + "/tiles"), store.status().cache_bytes);
  }
  // The newest tiles are held, the oldest went first.
  const std::size_t fetched = store.status().tiles_fetched;
  store.fetch({ids[7]});
  EXPECT_EQ(store.status().tiles_fetched, fetched);
  store.fetch({ids[0]});
  EXPECT_EQ(store.status().tiles_fetched, fetched + 1);
}

TEST_F(MapStoreTest, TheCacheSurvivesARestartAndServesOfflineWhatItHolds) {
  const std::vector<std::string> ids = map_->ids();
  std::string dir;
  {
    gpl::MapStore store(url(), config_);
    store.fetch({ids[0], ids[1]});
    dir = store.cacheDirectory();
  }
  writeFile(dir + "/tiles/.tmp-999999999-0-x", "half a file");  // a write of a process that died
  server_->stop();
  gpl::MapStore store(url(), config_);  // starts on the cached index
  EXPECT_FALSE(store.status().reachable);
  const auto fetched = store.fetch({ids[0], ids[1], ids[2]});
  EXPECT_TRUE(readFile(fetched[0].path) == map_->bytes(ids[0]));
  EXPECT_TRUE(readFile(fetched[1].path) == map_->bytes(ids[1]));
  EXPECT_NE(fetched[2].error, "");
  EXPECT_EQ(store.status().tiles_fetched, 0u);
  struct stat st {};
  EXPECT_NE(::stat((dir + "/tiles/.tmp-999999999-0-x").c_str(), &st), 0);  // dropped at start-up
  // A cached file damaged on disk is caught by its checksum and fetched again.
  server_->start();
  writeFile(fetched[0].path, std::string(map_->bytes(ids[0]).size(), 'z'));
  const auto again = store.fetch({ids[0]});
  EXPECT_TRUE(readFile(again[0].path) == map_->bytes(ids[0]));
  EXPECT_EQ(store.status().tiles_fetched, 1u);
}

TEST_F(MapStoreTest, AHostileIndexIsRefusedNamingTheTile) {
  map_->writeIndex(R"({"key":[0,0],"file":"../../etc/passwd.pcd","bytes":10})");
  try {
    gpl::MapStore store(url(), config_);
    FAIL() << "a tile name with '..' was accepted";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("../../etc/passwd.pcd"), std::string::npos) << what;
    EXPECT_NE(what.find(url() + "/index.json"), std::string::npos) << what;
  }
  map_->writeIndex(R"({"key":[0,0],"file":"/etc/passwd.pcd","bytes":10})");
  EXPECT_THROW(gpl::MapStore(url(), config_), std::invalid_argument);
}

TEST_F(MapStoreTest, IdsOutsideTheIndexAndBadUrlsAreRefused) {
  gpl::MapStore store(url(), config_);
  const auto fetched = store.fetch({"../index", "9.0_9.0"});
  EXPECT_NE(fetched[0].error.find("'..'"), std::string::npos) << fetched[0].error;
  EXPECT_NE(fetched[1].error.find("not in the index of " + url()), std::string::npos) << fetched[1].error;
  for (const std::string bad : {"ftp://127.0.0.1/map", "http://user:pw@127.0.0.1/map", "http://127.0.0.1/map?x=1",
                                "http:///map", "http://127.0.0.1/ma p"}) {
    try {
      gpl::MapStore s(bad, config_);
      ADD_FAILURE() << bad << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(bad), std::string::npos) << e.what();
    }
  }
  EXPECT_EQ(gpl::unsafeTileName("1.0_-3.0.pcd"), "");
  EXPECT_NE(gpl::unsafeTileName("a/b.pcd"), "");
  EXPECT_NE(gpl::unsafeTileName(".hidden"), "");
}

TEST_F(MapStoreTest, ABearerTokenFromAFileOrTheEnvironmentIsSent) {
  EXPECT_THROW(gpl::MapStore(server_->url("/auth"), config_), std::invalid_argument);  // 401 without it
  writeFile(cache_ + "/token", "s3cret\n");
  config_.bearer_token_file = cache_ + "/token";
  gpl::MapStore store(server_->url("/auth"), config_);
  EXPECT_EQ(store.fetch({map_->ids()[0]})[0].error, "");
  config_.bearer_token_file.clear();
  ::setenv("GPL_TEST_MAP_TOKEN", "s3cret", 1);
  config_.bearer_token_env = "GPL_TEST_MAP_TOKEN";
  EXPECT_NO_THROW(gpl::MapStore(server_->url("/auth"), config_));
  ::unsetenv("GPL_TEST_MAP_TOKEN");
}

TEST_F(MapStoreTest, AnIndexWithoutChecksumsIsCheckedBySize) {
  map_->writeAll(false);
  gpl::MapStore store(url(), config_);
  EXPECT_FALSE(store.index().checksums());
  const std::vector<std::string> ids = map_->ids();
  writeFile(map_->path(ids[1]), map_->bytes(ids[1]).substr(0, 10));
  const auto fetched = store.fetch({ids[0], ids[1]});
  EXPECT_TRUE(readFile(fetched[0].path) == map_->bytes(ids[0]));
  EXPECT_NE(fetched[1].error.find("truncated"), std::string::npos) << fetched[1].error;
}

// ---- the map worker reads a tile directory given by URL through the store

namespace {

// The synthetic world cut into 2 m tiles, written as `gpm tile` lays them out (binary PCDs + index.json with sizes
// and checksums) under root/map.
struct ServedWorld {
  ServedWorld() : root(makeTempDir()), tiles(gpl::test::cutTileStems(gpl::test::makeWorld(), 2.0)) {
    ::mkdir((root + "/map").c_str(), 0755);
    gpl::test::writeTiles(root + "/map", tiles);
    std::string entries;
    for (const auto& [id, cloud] : tiles) {
      ids.push_back(id);
      const std::string bytes = readFile(root + "/map/" + id + ".pcd");
      const gpl::TileKey key = gpl::tileKeyOfStem(id, 2.0);
      entries += std::string(entries.empty() ? "" : ",") + R"({"key":[)" + std::to_string(key.i) + "," +
                 std::to_string(key.j) + R"(],"file":")" + id + R"(.pcd","bytes":)" + std::to_string(bytes.size()) +
                 R"(,"sha256":")" + gpl::sha256Hex(bytes) + "\"}";
    }
    index = R"({"format":"grid_puzzle_tiles","version":1,"grid_size":2.0,"tiles":[)" + entries + "]}";
    writeFile(root + "/map/index.json", index);
  }
  ~ServedWorld() { std::system(("rm -rf '" + root + "'").c_str()); }
  std::string revision() const { return "sha256:" + gpl::sha256Hex(index).substr(0, 16); }
  std::string root, index;
  std::map<std::string, gpl::PointCloud> tiles;
  std::vector<std::string> ids;
};

gpl::MapChange fileChange(const std::string& dir, const std::string& revision, bool reset,
                          std::vector<std::string> added, std::vector<std::string> removed = {}) {
  gpl::TileFileChange f;
  f.dir = dir;
  f.index_revision = revision;
  f.reset = reset;
  f.added = std::move(added);
  f.removed = std::move(removed);
  return gpl::MapChange::tileFiles(2.0, std::move(f));
}

void expectSameVoxels(const gpl::VoxelMap& a, const gpl::VoxelMap& b) {
  ASSERT_EQ(a.voxelCount(), b.voxelCount());
  ASSERT_EQ(a.pointCount(), b.pointCount());
  a.forEach([&](const gpl::VoxelKey& key, const gpl::VoxelStats& st, const gpl::VoxelGaussian&) {
    const gpl::VoxelStats* o = b.stats(key);
    ASSERT_NE(o, nullptr);
    EXPECT_EQ(o->count, st.count);
    for (int i = 0; i < 3; ++i) EXPECT_EQ(o->sum[i], st.sum[i]);
  });
}

// The served world behind nginx at url(), and a map store configuration with its own disk cache.
class MapWorkerOverHttp : public ::testing::Test {
 protected:
  void SetUp() override {
    if (NginxServer::binary().empty()) GTEST_SKIP() << "nginx is not installed (apt-get install nginx-light)";
    server_ = std::make_unique<NginxServer>(world_.root);
    server_->start();
    cache_ = makeTempDir();
    config_.cache_dir = cache_;
    config_.retry_backoff = 0.01;
  }
  void TearDown() override {
    if (!cache_.empty()) std::system(("rm -rf '" + cache_ + "'").c_str());
  }

  std::string url() const { return server_->url("/map"); }

  // A localizer for scans of makeWorld() from a sensor at kMount (a 0.4 m scan voxel, 30 m range, the start search on
  // the scan thread) whose tiles come through the map store with config_.
  std::unique_ptr<gpl::Localizer> storeLocalizer() const {
    gpl::LocalizerConfig c;
    c.preprocess.voxel_size = 0.4;
    c.preprocess.max_range = 30.0;
    c.lost.background_search = false;
    auto loc = std::make_unique<gpl::Localizer>(c);
    loc->map().setMapStoreConfig(config_);
    return loc;
  }
  const Eigen::Isometry3d kMount = gpl::test::poseXYYaw(0.3, 0.0, 0.05, 1.8);  // base_T_sensor
  const gpl::PointCloud kWorld = gpl::test::makeWorld();

  ServedWorld world_;
  std::unique_ptr<NginxServer> server_;
  std::string cache_;
  gpl::MapStoreConfig config_;
};

}  // namespace

TEST_F(MapWorkerOverHttp, ATileDirectoryByUrlGivesTheTargetOfTheLocalDirectoryAndRidesOutTheServerGoingDown) {
  ASSERT_GE(world_.ids.size(), 60u);
  const std::string url = this->url();
  const std::vector<std::string> first(world_.ids.begin(), world_.ids.begin() + 40);
  const std::vector<std::string> enter(world_.ids.begin() + 40, world_.ids.begin() + 50);
  const std::vector<std::string> leave(world_.ids.begin(), world_.ids.begin() + 10);

  gpl::VoxelMapParams params;
  gpl::MapUpdateWorker remote(params), local(params);
  remote.setMapStoreConfig(config_);
  remote.submit(fileChange(url, world_.revision(), true, first));
  remote.waitIdle();  // the second change would otherwise join the first, and its leaving tiles go unfetched
  remote.submit(fileChange(url, world_.revision(), false, enter, leave));
  local.submit(fileChange(world_.root + "/map", "r", true, first));
  local.submit(fileChange(world_.root + "/map", "r", false, enter, leave));
  remote.waitIdle();
  local.waitIdle();
  EXPECT_EQ(remote.takeErrors(), std::vector<std::string>());
  const auto by_url = remote.takeReady();
  const auto by_path = local.takeReady();
  ASSERT_TRUE(by_url && by_path);
  expectSameVoxels(*by_url, *by_path);
  EXPECT_EQ(remote.stats().tiles, 40u);
  EXPECT_EQ(remote.stats().map_store_fetched, 50u);

  // Server down: tiles not held are reported by URL, the loaded ones stay, the status says unreachable.
  server_->stop();
  remote.submit(fileChange(url, world_.revision(), false, {world_.ids[55]}));
  remote.waitIdle();
  const std::vector<std::string> errors = remote.takeErrors();
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_NE(errors[0].find(url + "/" + world_.ids[55] + ".pcd"), std::string::npos) << errors[0];
  EXPECT_EQ(remote.stats().tiles, 40u);
  EXPECT_FALSE(remote.stats().map_store_reachable);
  EXPECT_NE(remote.stats().map_store_error.find(url), std::string::npos) << remote.stats().map_store_error;
  // Back: the next delta also fetches the tile that failed.
  server_->start();
  remote.submit(fileChange(url, world_.revision(), false, {world_.ids[56]}));
  remote.waitIdle();
  EXPECT_EQ(remote.takeErrors(), std::vector<std::string>());
  EXPECT_EQ(remote.stats().tiles, 42u);
  EXPECT_EQ(remote.stats().map_store_fetched, 52u);
  EXPECT_TRUE(remote.stats().map_store_reachable);
  // A reset of the window: the tiles held come from the disk cache.
  std::vector<std::string> window(world_.ids.begin() + 10, world_.ids.begin() + 50);
  window.push_back(world_.ids[55]);
  remote.submit(fileChange(url, world_.revision(), true, window));
  remote.waitIdle();
  EXPECT_EQ(remote.takeErrors(), std::vector<std::string>());
  EXPECT_EQ(remote.stats().tiles, 41u);
  EXPECT_EQ(remote.stats().map_store_fetched, 52u);

  // A delta naming another revision than the server's index is refused whole: no tiles of two revisions.
  remote.submit(fileChange(url, "sha256:0000000000000000", false, {world_.ids[57]}));
  remote.waitIdle();
  const std::vector<std::string> refused = remote.takeErrors();
  ASSERT_EQ(refused.size(), 1u);
  EXPECT_NE(refused[0].find("revision"), std::string::npos) << refused[0];
  EXPECT_EQ(remote.stats().tiles, 41u);
}

TEST_F(MapWorkerOverHttp, AfterAnOutageEachChangeRetriesOneFetchBatchOfTheFailedTilesTheLatestFirst) {
  const std::size_t batch = gpl::kTileFetchBatch, late = 5;  // `late` tiles more than one batch failed
  ASSERT_GE(world_.ids.size(), 10 + batch + late);
  const std::string url = this->url();
  gpl::MapUpdateWorker worker{gpl::VoxelMapParams()};
  worker.setMapStoreConfig(config_);
  worker.submit(fileChange(url, world_.revision(), true, {world_.ids.begin(), world_.ids.begin() + 10}));
  worker.waitIdle();
  ASSERT_EQ(worker.stats().tiles, 10u);

  // The server goes down while the window moves on: every entering tile fails (in this order).
  server_->stop();
  const std::vector<std::string> entering(world_.ids.begin() + 10, world_.ids.begin() + 10 + batch + late);
  worker.submit(fileChange(url, world_.revision(), false, entering));
  worker.waitIdle();
  EXPECT_EQ(worker.takeErrors().size(), entering.size());
  EXPECT_EQ(worker.stats().tiles, 10u);

  // Back: the next change fetches one batch of them, not the whole backlog.
  server_->start();
  worker.submit(fileChange(url, world_.revision(), false, {}));
  worker.waitIdle();
  EXPECT_EQ(worker.takeErrors(), std::vector<std::string>());
  EXPECT_TRUE(worker.stats().map_store_reachable);
  EXPECT_EQ(worker.stats().tiles, 10 + batch);
  // The ones left are the earliest failures: they leave the window unloaded (the count stays) and are not fetched.
  const std::vector<std::string> earliest(entering.begin(), entering.begin() + late);
  worker.submit(fileChange(url, world_.revision(), false, {}, earliest));
  worker.waitIdle();
  worker.submit(fileChange(url, world_.revision(), false, {}));
  worker.waitIdle();
  EXPECT_EQ(worker.takeErrors(), std::vector<std::string>());
  EXPECT_EQ(worker.stats().tiles, 10 + batch);
  EXPECT_EQ(worker.stats().map_store_fetched, 10 + batch);
}

// ---- a window from a slow store arrives nearest the vehicle first and is matched on as it arrives

TEST_F(MapWorkerOverHttp, ASlowWindowIsPublishedAsItArrivesNearestTheFocusFirstWithWhatIsStillInFlight) {
  // nginx behind bench/delay_proxy.py: at most 300 requests a second, all connections together (600 tiles: 2 s).
  const gpl_test::DelayProxyServer slow(server_->port(), 300.0);
  gpl::MapUpdateWorker worker{gpl::VoxelMapParams()};
  worker.setMapStoreConfig(config_);
  const Eigen::Vector2d focus(12.0, -7.0);
  worker.setFocus(focus);
  worker.submit(fileChange(slow.url("/map"), world_.revision(), true, world_.ids));
  // The first snapshot announces the whole window in flight before any tile arrives (no map yet).
  std::optional<gpl::MapSnapshot> announced, partial, latest;
  while (worker.busy()) {
    if (std::optional<gpl::MapSnapshot> s = worker.takeSnapshot()) {
      if (!announced && !latest) announced = s;
      if (!partial && s->map && !s->in_flight.keys.empty()) partial = s;
      if (s->map) latest = std::move(s);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  worker.waitIdle();
  if (std::optional<gpl::MapSnapshot> s = worker.takeSnapshot()) latest = std::move(s);
  EXPECT_EQ(worker.takeErrors(), std::vector<std::string>());
  ASSERT_TRUE(announced);
  EXPECT_EQ(announced->map, nullptr);
  EXPECT_EQ(announced->in_flight.keys.size(), world_.ids.size());
  ASSERT_TRUE(partial) << "no snapshot while the window was loading";
  EXPECT_GE(worker.stats().partial_snapshots, 1u);

  // The partial map is exactly the tiles not in flight, read from disk, and they are the ones nearest the focus.
  std::set<std::pair<std::int64_t, std::int64_t>> flying;
  for (const gpl::TileKey& k : partial->in_flight.keys) flying.insert({k.i, k.j});
  std::vector<std::string> held;
  double farthest_held = 0.0, nearest_flying = std::numeric_limits<double>::infinity();
  for (const std::string& id : world_.ids) {
    const gpl::TileKey k = gpl::tileKeyOfStem(id, 2.0);
    const double d = (Eigen::Vector2d(2.0 * k.i + 1.0, 2.0 * k.j + 1.0) - focus).cwiseAbs().maxCoeff();
    if (flying.count({k.i, k.j})) {
      nearest_flying = std::min(nearest_flying, d);
    } else {
      held.push_back(id);
      farthest_held = std::max(farthest_held, d);
    }
  }
  ASSERT_FALSE(held.empty());
  EXPECT_EQ(held.size() + flying.size(), world_.ids.size());
  EXPECT_LE(farthest_held, nearest_flying);
  EXPECT_EQ(partial->in_flight.within(focus, 1.0), 0u);
  gpl::MapUpdateWorker local{gpl::VoxelMapParams()};
  local.submit(fileChange(world_.root + "/map", "r", true, held));
  local.waitIdle();
  expectSameVoxels(*partial->map, *local.takeReady());

  // Loaded: nothing in flight, the whole window.
  ASSERT_TRUE(latest);
  EXPECT_TRUE(latest->in_flight.keys.empty());
  local.submit(fileChange(world_.root + "/map", "r", true, world_.ids));
  local.waitIdle();
  expectSameVoxels(*latest->map, *local.takeReady());
}

// The window moves on while a slow window loads: the change joins the one loading. Its leaving tiles not fetched yet
// are never fetched, its entering ones are in flight at once, and the map ends as the final window read from disk.
TEST_F(MapWorkerOverHttp, AChangeQueuedWhileASlowWindowLoadsJoinsIt) {
  const gpl_test::DelayProxyServer slow(server_->port(), 300.0);
  gpl::MapUpdateWorker worker{gpl::VoxelMapParams()};
  worker.setMapStoreConfig(config_);
  const std::size_t half = world_.ids.size() / 2;
  const std::vector<std::string> first(world_.ids.begin(), world_.ids.begin() + half);
  const std::vector<std::string> entering(world_.ids.begin() + half, world_.ids.end());
  // Nearest the focus first: the tiles farthest from it are the last of the first window to be fetched.
  const Eigen::Vector2d focus = gpl::tileCentre(gpl::tileKeyOfStem(first.front(), 2.0), 2.0);
  worker.setFocus(focus);
  std::vector<std::string> by_distance = first;
  std::sort(by_distance.begin(), by_distance.end(), [&](const std::string& a, const std::string& b) {
    return (gpl::tileCentre(gpl::tileKeyOfStem(a, 2.0), 2.0) - focus).norm() <
           (gpl::tileCentre(gpl::tileKeyOfStem(b, 2.0), 2.0) - focus).norm();
  });
  const std::vector<std::string> leaving(by_distance.end() - static_cast<std::ptrdiff_t>(half / 4), by_distance.end());
  worker.submit(fileChange(slow.url("/map"), world_.revision(), true, first));
  // Once the first window is loading (announced in flight), the window moves on.
  std::optional<gpl::MapSnapshot> s;
  while (!(s = worker.takeSnapshot())) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  worker.submit(fileChange(slow.url("/map"), world_.revision(), false, entering, leaving));
  bool entering_in_flight = false;
  std::shared_ptr<const gpl::VoxelMap> map;
  const gpl::TileKey entering_key = gpl::tileKeyOfStem(entering.front(), 2.0);
  const auto take = [&] {
    if (!(s = worker.takeSnapshot())) return;
    for (const gpl::TileKey& f : s->in_flight.keys) entering_in_flight = entering_in_flight || f == entering_key;
    if (s->map) map = s->map;
  };
  while (worker.busy()) {
    take();
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  worker.waitIdle();
  take();
  EXPECT_EQ(worker.takeErrors(), std::vector<std::string>());
  EXPECT_TRUE(entering_in_flight) << "the joining change's tiles were never announced in flight while loading";
  // 2 s of fetching at 300 tiles/s: the farthest quarter of the first window had not been fetched when it left.
  EXPECT_EQ(worker.stats().map_store_fetched, world_.ids.size() - leaving.size());
  std::vector<std::string> final_window;
  for (const std::string& id : world_.ids)
    if (std::find(leaving.begin(), leaving.end(), id) == leaving.end()) final_window.push_back(id);
  gpl::MapUpdateWorker local{gpl::VoxelMapParams()};
  local.submit(fileChange(world_.root + "/map", "r", true, final_window));
  local.waitIdle();
  ASSERT_TRUE(map);
  expectSameVoxels(*map, *local.takeReady());
  EXPECT_EQ(worker.stats().tiles, final_window.size());
}

TEST_F(MapWorkerOverHttp, AStartOnASlowStoreWaitsForTheTilesAroundItAndIsNotLostMeanwhile) {
  const gpl_test::DelayProxyServer slow(server_->port(), 300.0);
  const std::unique_ptr<gpl::Localizer> localizer = storeLocalizer();
  gpl::Localizer& loc = *localizer;
  const Eigen::Isometry3d standing = gpl::test::poseXYYaw(-12.0, 2.0, 0.2);  // the vehicle waits at its start
  loc.map().setFocus(standing.translation().head<2>());
  loc.setInitialPose(standing);
  loc.map().submit(fileChange(slow.url("/map"), world_.revision(), true, world_.ids));
  std::size_t waited_for_tiles = 0, tracked = 0, in_flight_at_first_pose = 0;
  for (int i = 0; tracked < 10 && i < 2000; ++i) {
    const gpl::LocalizerOutput out =
        loc.processScan(0.1 * i, gpl::test::scanFrom(kWorld, standing * kMount, 30.0f, 0.01f, i), kMount);
    EXPECT_FALSE(out.lost) << "scan " << i << ": lost on a window still arriving";
    if (out.state == gpl::LocalizerState::kWaitingForMap) {
      EXPECT_FALSE(out.publish);
      if (out.tiles_awaited > 0 && waited_for_tiles++ == 0) {
        // A start search over the same tiles waits for them too, without running.
        gpl::SearchRegion region;
        region.centre = standing;
        region.radius = 10.0;
        const std::optional<gpl::StartSearch> search = loc.startSearchForStart(region);
        ASSERT_TRUE(search);
        EXPECT_GT(search->tiles_awaited, 0u);
        EXPECT_FALSE(search->search.found);
        EXPECT_FALSE(loc.searching());
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      continue;
    }
    ASSERT_EQ(out.state, gpl::LocalizerState::kTracking);
    if (tracked++ == 0) {
      in_flight_at_first_pose = out.tiles_in_flight;
      // Matched once the tiles around the start had arrived, not before.
      EXPECT_EQ(loc.tilesAwaited(standing.translation().head<2>(), loc.config().map_wait_half_side), 0u);
    }
    EXPECT_TRUE(out.match_accepted) << "scan " << i;
    EXPECT_LT(gpl::test::translationError(out.pose, standing), 0.05) << "scan " << i;
  }
  EXPECT_EQ(tracked, 10u);
  EXPECT_GT(waited_for_tiles, 0u) << "the start never waited for tiles around it";
  EXPECT_GT(in_flight_at_first_pose, 0u) << "the start waited for the whole window, not the tiles around it";

  // Once the whole window is there, a scan that fits nowhere is lost, and says it waited for nothing.
  loc.map().waitIdle();
  gpl::PointCloud noise;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-20.0f, 20.0f);
  for (int k = 0; k < 3000; ++k) noise.push_back(gpl::Point(u(rng), u(rng), 0.1f * u(rng)));
  gpl::LocalizerOutput out;
  for (int k = 0; k < 3; ++k) out = loc.processScan(300.0 + 0.1 * k, noise, kMount);
  EXPECT_TRUE(out.lost);
  EXPECT_EQ(out.tiles_awaited, 0u);
  EXPECT_EQ(out.tiles_in_flight, 0u);
}

// The vehicle drives into a part of the window still arriving (it outran a slow store): the track waits there,
// carried by its scans, instead of matching on the part that has come, and is never published off; it tracks again
// once the tiles around it are in.
TEST_F(MapWorkerOverHttp, ATrackDrivingIntoTilesStillInFlightWaitsCarriedAndIsNeverPublishedOff) {
  const gpl_test::DelayProxyServer slow(server_->port(), 100.0);
  const std::unique_ptr<gpl::Localizer> localizer = storeLocalizer();
  gpl::Localizer& loc = *localizer;
  const auto truth = [](double t) { return gpl::test::poseXYYaw(-20.0 + 4.0 * t, 1.0, 0.0); };
  std::vector<std::string> west, east;
  for (const std::string& id : world_.ids) (gpl::tileKeyOfStem(id, 2.0).i < -2 ? west : east).push_back(id);
  loc.map().submit(fileChange(slow.url("/map"), world_.revision(), true, west));
  loc.map().waitIdle();
  loc.setInitialPose(truth(0.0));
  std::size_t waited = 0, published = 0;
  gpl::LocalizerOutput out;
  for (int i = 0; i < 70; ++i) {
    const double t = 0.1 * i;
    if (i == 10) loc.map().submit(fileChange(slow.url("/map"), world_.revision(), false, east));  // 100 tiles/s
    out = loc.processScan(t, gpl::test::scanFrom(kWorld, truth(t) * kMount, 30.0f, 0.01f, i), kMount);
    EXPECT_FALSE(out.lost) << "scan " << i;
    if (out.state == gpl::LocalizerState::kWaitingForMap) {
      EXPECT_TRUE(out.start_pending) << "scan " << i;
      EXPECT_FALSE(out.publish);
      EXPECT_GT(out.tiles_awaited, 0u);
      waited += out.tiles_awaited > 0;
    }
    if (out.publish) {
      ++published;
      EXPECT_LT(gpl::test::translationError(out.pose, truth(t)), 0.1) << "scan " << i << ", published off";
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));  // the scans come in real time
  }
  EXPECT_GT(waited, 0u) << "the track never waited for the tiles in flight around it";
  EXPECT_GE(published, 20u);
  ASSERT_EQ(out.state, gpl::LocalizerState::kTracking);
  EXPECT_TRUE(out.match_accepted);
  EXPECT_LT(gpl::test::translationError(out.pose, truth(6.9)), 0.05);
}

// ---- the provider's tile references follow a directory given by URL through its polled index

TEST_F(MapStoreTest, TheProvidersTileReferencesFollowAPolledRevision) {
  gpl::MapStore store(url(), config_);
  auto remote = std::make_shared<gpl::RemoteTileIndex>();
  gpl::TileDirectory directory = gpl::tileDirectoryOfIndex(store.url(), store.index(), 0.0);
  EXPECT_EQ(directory.grid_size, 2.0);
  EXPECT_EQ(directory.tiles.size(), 8u);
  remote->set(directory, store.status().revision);
  directory.remote = remote;
  gpl::TileReferences references(directory);
  EXPECT_EQ(references.revision(), store.status().revision);
  const gpl::TileBox box{0, 3, 0, 0};
  EXPECT_EQ(references.update(box, {}).added.size(), 4u);
  EXPECT_FALSE(references.refresh());
  // A new revision with a ninth tile: polled, handed over, and the references start again from it.
  map_->set(gpl::tileStem(8, 0, 2.0), std::string(100, 'q'));
  map_->writeAll();
  ASSERT_TRUE(store.pollIndex());
  remote->set(gpl::tileDirectoryOfIndex(store.url(), store.index(), 0.0), store.status().revision);
  EXPECT_TRUE(references.refresh());
  EXPECT_EQ(references.revision(), store.status().revision);
  EXPECT_EQ(references.directory().tiles.size(), 9u);
  EXPECT_EQ(references.directory().path, url());
  EXPECT_EQ(references.update(gpl::TileBox{0, 9, 0, 0}, {}).added.size(), 9u);
  EXPECT_THROW(gpl::tileDirectoryOfIndex(store.url(), store.index(), 3.0), std::invalid_argument);
}
