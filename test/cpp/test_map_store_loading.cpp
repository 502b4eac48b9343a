// The map store's library is loaded on the first MapStore, not before: a process on a local map never maps libcurl.
// This binary links the core alone, as the nodelets do, so MapStore takes the path a localizer takes (dlopen).
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <fstream>
#include <stdexcept>
#include <string>

#include "grid_puzzle_localization/map_store/map_store.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

bool mapsLibrary(const std::string& name) {
  std::ifstream maps("/proc/self/maps");
  std::string line;
  while (std::getline(maps, line))
    if (line.find(name) != std::string::npos) return true;
  return false;
}

// A localhost port nothing listens on: bound, read back, and closed again.
int closedPort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof(addr);
  if (fd < 0 || ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0)
    throw std::runtime_error("cannot bind a localhost port");
  ::close(fd);
  return ntohs(addr.sin_port);
}

}  // namespace

TEST(MapStoreLoading, TheFirstStoreLoadsLibcurlAndItsErrorsStillNameTheUrl) {
  EXPECT_TRUE(gpl::isMapStoreUrl("http://localhost/map"));
  EXPECT_FALSE(mapsLibrary("libcurl")) << "the core alone must not map libcurl";

  char cache[] = "/tmp/gpl_store_loading_XXXXXX";
  ASSERT_NE(::mkdtemp(cache), nullptr);
  gpl::MapStoreConfig config;
  config.cache_dir = cache;
  config.max_retries = 0;
  config.connect_timeout = 2.0;
  const std::string url = "http://127.0.0.1:" + std::to_string(closedPort()) + "/map";
  try {
    gpl::MapStore store(url, config);
    FAIL() << "a store on a port nothing listens on opened";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(url), std::string::npos) << what;
    EXPECT_NE(what.find("check the URL and that the server runs"), std::string::npos) << what;
  }
  EXPECT_TRUE(mapsLibrary("libgrid_puzzle_localization_map_store")) << "the store's library was not loaded";
  EXPECT_TRUE(mapsLibrary("libcurl"));
  std::system(("rm -rf " + std::string(cache)).c_str());
}
