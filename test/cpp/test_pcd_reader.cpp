// The core PCD reader against files written here byte by byte and against PCL's reader on real files.
#include <ftw.h>
#include <gtest/gtest.h>
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>
#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <vector>

#include "grid_puzzle_localization/pcd_reader.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

std::string tempPath(const std::string& name) { return ::testing::TempDir() + "/gpl_pcd_" + name; }

void write(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out << bytes;
}

std::string readAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}

const std::string kTestData = std::string(GPL_SOURCE_DIR) + "/test/data";  // committed real files
// The team's larger store: $GPL_SHARED_DATA, else ../shared/data/real beside the clone.
std::string sharedData() {
  const char* env = std::getenv("GPL_SHARED_DATA");
  return env && *env ? std::string(env) : std::string(GPL_SOURCE_DIR) + "/../shared/data/real";
}

bool isDirectory(const std::string& path) {
  struct stat st;
  return ::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode);
}

std::vector<std::string> found;  // nftw's callback takes no user data
int collectPcd(const char* path, const struct stat*, int type, struct FTW*) {
  const std::string p(path);
  if (type == FTW_F && p.size() > 4 && p.compare(p.size() - 4, 4, ".pcd") == 0) found.push_back(p);
  return 0;
}

// Every .pcd file under `dir`, sorted (POSIX nftw: GCC 9's std::filesystem needs an extra library).
std::vector<std::string> pcdFilesUnder(const std::string& dir) {
  found.clear();
  EXPECT_EQ(::nftw(dir.c_str(), collectPcd, 16, FTW_PHYS), 0) << dir;
  std::sort(found.begin(), found.end());
  return found;
}

// Bitwise equal x, y, z (NaN included) to what PCL reads.
void expectSameAsPcl(const std::string& path) {
  SCOPED_TRACE(path);
  pcl::PointCloud<pcl::PointXYZ> ref;
  ASSERT_EQ(pcl::io::loadPCDFile(path, ref), 0);
  const gpl::PointCloud ours = gpl::readPcdXyz(path);
  ASSERT_EQ(ours.size(), ref.size());
  for (std::size_t i = 0; i < ours.size(); ++i)
    ASSERT_EQ(std::memcmp(ours[i].data(), ref[i].data, 3 * sizeof(float)), 0) << "point " << i;
}

// A copy of a real file whose header claims `fewer` points less than its data holds (WIDTH and POINTS lowered):
// the zero-padded files some recorders write.
std::string paddedCopy(const std::string& path, std::size_t fewer, const std::string& name) {
  std::string bytes = readAll(path);
  for (const std::string key : {"WIDTH ", "POINTS "}) {
    const std::size_t at = bytes.find("\n" + key) + 1 + key.size();
    const std::size_t end = bytes.find('\n', at);
    const std::size_t n = std::stoul(bytes.substr(at, end - at));
    bytes.replace(at, end - at, std::to_string(n - fewer));
  }
  const std::string out = tempPath(name);
  write(out, bytes);
  return out;
}

TEST(PcdReader, AsciiWithExtraFieldsAndCounts) {
  const std::string path = tempPath("ascii.pcd");
  write(path,
        "# .PCD v0.7\nVERSION 0.7\nFIELDS intensity x y z rgb\nSIZE 4 4 4 8 4\nTYPE F F F F U\nCOUNT 2 1 1 1 1\n"
        "WIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n"
        "1 2 0.5 -1.25 3 7\n9 9 nan 4 -2.5e1 0\n");
  const gpl::PointCloud c = gpl::readPcdXyz(path);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c[0], gpl::Point(0.5f, -1.25f, 3.0f));
  EXPECT_TRUE(std::isnan(c[1].x()));
  EXPECT_EQ(c[1].y(), 4.0f);
  EXPECT_EQ(c[1].z(), -25.0f);
}

TEST(PcdReader, BinaryFloat64AnyFieldOrder) {
  const std::string path = tempPath("binary.pcd");
  std::string bytes =
      "VERSION 0.7\nFIELDS z pad x y\nSIZE 8 2 4 8\nTYPE F U F F\nCOUNT 1 1 1 1\nWIDTH 3\nHEIGHT 1\nPOINTS 3\n"
      "DATA binary\n";
  for (int i = 0; i < 3; ++i) {
    const double z = 100.0 + i, y = -0.125 * i;
    const float x = 1.5f * i;
    const std::uint16_t pad = 0xABCD;
    bytes.append(reinterpret_cast<const char*>(&z), 8);
    bytes.append(reinterpret_cast<const char*>(&pad), 2);
    bytes.append(reinterpret_cast<const char*>(&x), 4);
    bytes.append(reinterpret_cast<const char*>(&y), 8);
  }
  write(path, bytes);
  const gpl::PointCloud c = gpl::readPcdXyz(path);
  ASSERT_EQ(c.size(), 3u);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(c[i], gpl::Point(1.5f * i, -0.125f * i, 100.0f + i));
}

TEST(PcdReader, CommittedRealFilesMatchPcl) {
  const std::vector<std::string> files = pcdFilesUnder(kTestData);
  ASSERT_GE(files.size(), 4u);  // binary (x y z intensity) and binary_compressed (LZF)
  for (const std::string& f : files) expectSameAsPcl(f);
}

TEST(PcdReader, EveryFileOfTheSharedRealDataMatchesPcl) {
  const std::string dir = sharedData();
  if (!isDirectory(dir)) GTEST_SKIP() << dir << " absent (set GPL_SHARED_DATA to run this test)";
  const std::vector<std::string> files = pcdFilesUnder(dir);
  EXPECT_GT(files.size(), 1000u);
  for (const std::string& f : files) expectSameAsPcl(f);
}

TEST(PcdReader, PaddedBinaryFileReadsPointsRecordsLikePcl) {
  const std::string real = kTestData + "/hdl32_pair/251370668.pcd";
  const std::string padded = paddedCopy(real, 327, "padded.pcd");
  expectSameAsPcl(padded);
  const gpl::PointCloud whole = gpl::readPcdXyz(real), head = gpl::readPcdXyz(padded);
  ASSERT_EQ(head.size(), whole.size() - 327);
  EXPECT_TRUE(std::equal(head.begin(), head.end(), whole.begin()));
}

TEST(PcdReader, PaddedAsciiFileReadsPointsLinesLikePcl) {
  const std::string path = tempPath("padded_ascii.pcd");
  write(path,
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\n"
        "DATA ascii\n1 2 3\n4 5 6\n7 8 9\n0 0 0\n");
  expectSameAsPcl(path);
  EXPECT_EQ(gpl::readPcdXyz(path).size(), 2u);
}

// Files PCL refuses as corrupt are refused, and a header's count is checked against the file before anything
// that size is allocated (a claim of 10^15 points must fail fast, not throw std::bad_alloc).
TEST(PcdReader, TruncatedAndOverclaimingFilesAreRefusedLikePcl) {
  const std::string header =
      "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\nPOINTS {n}\nDATA {e}\n";
  const auto make = [&](const std::string& name, const std::string& n, const std::string& e, const std::string& d) {
    std::string text = header;
    for (int k = 0; k < 2; ++k) text.replace(text.find("{n}"), 3, n);
    text.replace(text.find("{e}"), 3, e);
    const std::string path = tempPath(name);
    write(path, text + d);
    return path;
  };
  const std::string real_cut = tempPath("real_cut.pcd");
  const std::string real = readAll(kTestData + "/hdl32_pair/251370668.pcd");
  write(real_cut, real.substr(0, real.size() - 7));
  const std::string compressed_cut = tempPath("compressed_cut.pcd");
  const std::string lzf = readAll(kTestData + "/isprs_terrain_utm/samp11-utm.pcd");
  write(compressed_cut, lzf.substr(0, lzf.size() - 5000));  // PCL pads compressed files by about 4 kB
  const std::string ascii_short = make("ascii_short.pcd", "3", "ascii", "1 2 3\n4 5 6\n");
  const std::string huge_binary = make("huge_binary.pcd", "1000000000000000", "binary", std::string(120, '\0'));
  const std::string huge_ascii = make("huge_ascii.pcd", "1000000000000000", "ascii", "1 2 3\n");
  std::string sizes(8, '\0');  // a compressed block claiming 4 GB from 16 bytes
  const std::uint32_t packed = 16, unpacked = 0xFFFFFFF0u;
  std::memcpy(&sizes[0], &packed, 4);
  std::memcpy(&sizes[4], &unpacked, 4);
  const std::string huge_lzf = make("huge_lzf.pcd", "357913940", "binary_compressed", sizes + std::string(16, '\0'));
  for (const std::string& path : {real_cut, compressed_cut, ascii_short, huge_binary, huge_ascii, huge_lzf}) {
    SCOPED_TRACE(path);
    pcl::PCLPointCloud2 ref;
    if (path != huge_lzf) {  // PCL itself trusts the LZF sizes
      EXPECT_LT(pcl::io::loadPCDFile(path, ref), 0);
    }
    try {
      gpl::readPcdXyz(path);
      ADD_FAILURE() << "expected PcdReadError";
    } catch (const gpl::PcdReadError& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
    }
  }
}

TEST(PcdReader, ErrorsNameTheFileAndTheProblem) {
  try {
    gpl::readPcdXyz(tempPath("does_not_exist.pcd"));
    FAIL() << "expected PcdReadError";
  } catch (const gpl::PcdReadError& e) {
    EXPECT_NE(std::string(e.what()).find("does_not_exist.pcd"), std::string::npos);
  }
  const std::string no_z = tempPath("no_z.pcd");
  write(no_z, "VERSION 0.7\nFIELDS x y\nSIZE 4 4\nTYPE F F\nCOUNT 1 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2\n");
  try {
    gpl::readPcdXyz(no_z);
    FAIL() << "expected PcdReadError";
  } catch (const gpl::PcdReadError& e) {
    EXPECT_NE(std::string(e.what()).find("'z'"), std::string::npos);
  }
  const std::string truncated = tempPath("truncated.pcd");
  write(truncated,
        "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 10\nHEIGHT 1\nPOINTS 10\n"
        "DATA binary\n0123456789");
  EXPECT_THROW(gpl::readPcdXyz(truncated), gpl::PcdReadError);
  const std::string text = tempPath("text.pcd");
  write(text, "hello world\n");
  EXPECT_THROW(gpl::readPcdXyz(text), gpl::PcdReadError);
}

}  // namespace
