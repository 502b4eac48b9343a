// libFuzzer target: readPcdXyz on arbitrary file contents. A rejected input must throw PcdReadError naming
// the file; any other exception, crash, sanitizer report or oversized allocation is a finding.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "grid_puzzle_localization/pcd_reader.hpp"

namespace {

// The reader takes a path, so every input goes through one file of a private directory (tmpfs when
// TMPDIR points there).
const std::string& inputPath() {
  static const std::string path = [] {
    const char* tmp = std::getenv("TMPDIR");
    std::string dir = std::string(tmp ? tmp : "/tmp") + "/fuzz_pcd_XXXXXX";
    if (!mkdtemp(dir.data())) std::abort();
    return dir + "/input.pcd";
  }();
  return path;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string& path = inputPath();
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f || std::fwrite(data, 1, size, f) != size || std::fclose(f) != 0) std::abort();
  try {
    grid_puzzle_localization::readPcdXyz(path);
  } catch (const grid_puzzle_localization::PcdReadError& e) {
    // The message must name the file so that a user with many tiles knows which one is bad.
    if (std::string(e.what()).find(path) == std::string::npos) std::abort();
  }
  return 0;
}
