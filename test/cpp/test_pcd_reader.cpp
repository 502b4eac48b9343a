// The core PCD reader against files written here byte by byte and against PCL's reader on real files.
#include <gtest/gtest.h>
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>

#include <cmath>
#include <cstdio>
#include <fstream>

#include "grid_puzzle_localization/pcd_reader.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

std::string tempPath(const std::string& name) { return ::testing::TempDir() + "/gpl_pcd_" + name; }

void write(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out << bytes;
}

const std::string kRealDir = std::string(GPL_SOURCE_DIR) + "/../shared/data/real";

void expectSameAsPcl(const std::string& path) {
  pcl::PointCloud<pcl::PointXYZ> ref;
  ASSERT_EQ(pcl::io::loadPCDFile(path, ref), 0);
  const gpl::PointCloud ours = gpl::readPcdXyz(path);
  ASSERT_EQ(ours.size(), ref.size());
  for (std::size_t i = 0; i < ours.size(); ++i) {
    ASSERT_EQ(ours[i].x(), ref[i].x) << i;
    ASSERT_EQ(ours[i].y(), ref[i].y) << i;
    ASSERT_EQ(ours[i].z(), ref[i].z) << i;
  }
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

TEST(PcdReader, RealBinaryAndCompressedFilesMatchPcl) {
  expectSameAsPcl(kRealDir + "/hdl32_pair/251370668.pcd");                 // binary, x y z intensity
  expectSameAsPcl(kRealDir + "/isprs_terrain_utm/samp11-utm-ground.pcd");  // binary_compressed (LZF)
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
