#include <gtest/gtest.h>

#include <cstring>

#include "point_cloud_msg.hpp"

namespace gpl = grid_puzzle_localization;
using sensor_msgs::PointField;

namespace {

sensor_msgs::PointField field(const std::string& name, std::uint32_t offset, std::uint8_t type) {
  PointField f;
  f.name = name;
  f.offset = offset;
  f.datatype = type;
  f.count = 1;
  return f;
}

template <class T>
void put(sensor_msgs::PointCloud2& msg, std::size_t byte, T value) {
  std::memcpy(msg.data.data() + byte, &value, sizeof value);
}

// 2 rows x 3 points with 4 padding bytes per row; x y z float32 at 0, time field `type` at 16 after 4
// bytes of intensity. Point k (row-major) is at (k, -k, 0.5 k) and was measured `seconds[k]` after the stamp.
sensor_msgs::PointCloud2 cloud(const std::string& time_name, std::uint8_t type, const double* seconds) {
  sensor_msgs::PointCloud2 msg;
  msg.height = 2;
  msg.width = 3;
  msg.fields = {field("x", 0, PointField::FLOAT32), field("y", 4, PointField::FLOAT32),
                field("z", 8, PointField::FLOAT32), field("intensity", 12, PointField::FLOAT32),
                field(time_name, 16, type)};
  msg.point_step = 24;
  msg.row_step = msg.point_step * msg.width + 4;
  msg.data.assign(static_cast<std::size_t>(msg.row_step) * msg.height, 0);
  for (int k = 0; k < 6; ++k) {
    const std::size_t at = (k / 3) * msg.row_step + (k % 3) * msg.point_step;
    put(msg, at, float(k));
    put(msg, at + 4, float(-k));
    put(msg, at + 8, 0.5f * k);
    if (type == PointField::FLOAT32) put(msg, at + 16, float(seconds[k]));
    if (type == PointField::FLOAT64) put(msg, at + 16, seconds[k]);
    if (type == PointField::UINT32) put(msg, at + 16, std::uint32_t(std::llround(seconds[k] * 1e9)));
  }
  return msg;
}

const double kSeconds[6] = {0.0, 0.0125, 0.025, 0.05, 0.075, 0.0999};

}  // namespace

TEST(PointCloudMsg, ReadsFloatSecondsAndOusterNanosecondsInPointOrder) {
  for (const auto& [name, type] : {std::pair<std::string, std::uint8_t>{"time", PointField::FLOAT32},
                                   {"time", PointField::FLOAT64},
                                   {"t", PointField::UINT32}}) {
    const sensor_msgs::PointCloud2 msg = cloud(name, type, kSeconds);
    const gpl::PointCloud points = gpl::fromMsg(msg);
    const std::optional<gpl::PointTimes> times = gpl::timesFromMsg(msg, name);
    ASSERT_TRUE(times.has_value()) << name;
    ASSERT_EQ(times->size(), points.size());
    for (int k = 0; k < 6; ++k) {
      EXPECT_EQ(points[k], gpl::Point(float(k), float(-k), 0.5f * k));
      EXPECT_FLOAT_EQ((*times)[k], float(kSeconds[k])) << name << " point " << k;  // stored as float
    }
  }
}

TEST(PointCloudMsg, MissingTimeFieldIsNoTimesAndAWrongTypeIsAClearError) {
  const sensor_msgs::PointCloud2 msg = cloud("time", PointField::FLOAT32, kSeconds);
  EXPECT_FALSE(gpl::timesFromMsg(msg, "t").has_value());
  const sensor_msgs::PointCloud2 bad = cloud("time", PointField::INT16, kSeconds);
  try {
    gpl::timesFromMsg(bad, "time");
    FAIL() << "an INT16 time field must be rejected";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'time'"), std::string::npos) << e.what();
  }
}

// Layouts the fuzzer (test/fuzz/fuzz_point_cloud_msg.cpp) found: a field reaching past point_step read past the
// buffer (or, with point_step 0, reserved 2^64 points); width 0 with 4e9 empty rows looped for seconds.
TEST(PointCloudMsg, FieldsOutsidePointStepAreRefused) {
  sensor_msgs::PointCloud2 msg = cloud("time", PointField::FLOAT64, kSeconds);
  msg.point_step = 20;  // the FLOAT64 time field at 16 needs 24
  EXPECT_NO_THROW(gpl::fromMsg(msg));
  EXPECT_THROW(gpl::timesFromMsg(msg, "time"), std::invalid_argument);
  msg.point_step = 8;  // z at 8 needs 12
  try {
    gpl::fromMsg(msg);
    FAIL() << "z outside point_step must be rejected";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'z'"), std::string::npos) << e.what();
  }
  msg.point_step = msg.row_step = 0;
  msg.width = msg.height = 0xffffffff;
  EXPECT_THROW(gpl::fromMsg(msg), std::invalid_argument);
}

TEST(PointCloudMsg, ZeroWidthIsAnEmptyCloudWhateverTheHeight) {
  sensor_msgs::PointCloud2 msg = cloud("time", PointField::FLOAT32, kSeconds);
  msg.width = msg.row_step = 0;
  msg.height = 0xffffffff;
  EXPECT_TRUE(gpl::fromMsg(msg).empty());
  EXPECT_TRUE(gpl::timesFromMsg(msg, "time")->empty());
}
