// Inputs the fuzzers (test/fuzz) found, and headers that claim far more points than their files hold: the core
// PCD reader refuses each with a PcdReadError naming the file, before allocating what the header claims (an
// allocation of 10^12 points would throw std::bad_alloc, or abort under ASan, instead).
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "grid_puzzle_localization/pcd_reader.hpp"

namespace gpl = grid_puzzle_localization;
namespace fs = std::filesystem;

namespace {

const fs::path kRegressions = fs::path(GPL_SOURCE_DIR) / "test" / "fuzz" / "regressions" / "pcd";

std::string write(const std::string& name, const std::string& bytes) {
  const std::string path = ::testing::TempDir() + "/gpl_bad_input_" + name;
  std::ofstream(path, std::ios::binary) << bytes;
  return path;
}

void expectRefused(const std::string& path, const std::string& why) {
  try {
    gpl::readPcdXyz(path);
    ADD_FAILURE() << path << " was accepted";
  } catch (const gpl::PcdReadError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(why), std::string::npos) << e.what();
  }
}

std::string header(const std::string& points, const std::string& data) {
  return "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH " + points + "\nHEIGHT 1\nPOINTS " +
         points + "\nDATA " + data + "\n";
}

}  // namespace

TEST(BadInput, FuzzRegressionsAreRefusedNamingTheFile) {
  ASSERT_TRUE(fs::is_directory(kRegressions));
  int files = 0;
  for (const auto& entry : fs::directory_iterator(kRegressions)) {
    const std::string path = ::testing::TempDir() + "/gpl_bad_input_" + entry.path().filename().string();
    fs::copy_file(entry.path(), path, fs::copy_options::overwrite_existing);
    expectRefused(path, "");
    ++files;
  }
  EXPECT_GT(files, 0);
}

TEST(BadInput, TrillionPointsRefusedBeforeAllocation) {
  const std::string point(12, '\0');
  expectRefused(write("trillion_binary.pcd", header("1000000000000", "binary") + point), "POINTS 1000000000000");
  expectRefused(write("trillion_ascii.pcd", header("1000000000000", "ascii") + "1 2 3\n"), "POINTS 1000000000000");
  // binary_compressed: sizes 3 bytes -> 12 (a valid LZF literal of the 12 zero bytes would be 13).
  const std::string sizes("\x0d\x00\x00\x00\x0c\x00\x00\x00", 8);
  expectRefused(write("trillion_compressed.pcd", header("1000000000000", "binary_compressed") + sizes + '\x0b' + point),
                "POINTS 1000000000000");
  // A POINTS beyond 2^64 / point size, whose byte count would wrap around.
  expectRefused(write("wrapping_binary.pcd", header("1537228672809129302", "binary") + point), "POINTS");
}

TEST(BadInput, CompressedSizeBeyondLzfExpansionRefused) {
  // 13 bytes cannot decompress to 4 GB (LZF expands 88x at most): refused before the 4 GB buffer.
  const std::string sizes("\x0d\x00\x00\x00\xf0\xff\xff\xff", 8);
  expectRefused(write("lzf_4gb.pcd", header("1", "binary_compressed") + sizes + std::string(13, '\0')),
                "cannot decompress to");
}

TEST(BadInput, DirectoryInPlaceOfTheFileRefusedNamingIt) {
  // As a tile replaced under the running localizer: opening succeeds, reading fails with EISDIR.
  const std::string path = ::testing::TempDir() + "/gpl_bad_input_directory.pcd";
  fs::create_directories(path);
  expectRefused(path, "cannot read it (Is a directory)");
}
