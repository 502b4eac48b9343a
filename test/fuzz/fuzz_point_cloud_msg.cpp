// libFuzzer target: PointCloud2 -> core cloud conversion of the nodelets (fromMsg, timesFromMsg) on messages
// whose layout (width, height, point_step, row_step, field offsets and types, endianness) and data come from
// the input. The nodelets catch std::invalid_argument only, so any other exception is a finding too.
#include <fuzzer/FuzzedDataProvider.h>

#include <cstdint>
#include <cstdlib>
#include <stdexcept>
#include <string>

#include "point_cloud_msg.hpp"

namespace {

const char* const kNames[] = {"x", "y", "z", "t", "time", "intensity"};

sensor_msgs::PointCloud2 message(FuzzedDataProvider& in) {
  sensor_msgs::PointCloud2 msg;
  // Small values most of the time (so inputs reach the copy loops), any value sometimes (overflow).
  auto dimension = [&in] {
    return in.ConsumeBool() ? in.ConsumeIntegral<std::uint32_t>() : in.ConsumeIntegralInRange<std::uint32_t>(0, 64);
  };
  msg.height = dimension();
  msg.width = dimension();
  msg.point_step = dimension();
  msg.row_step = dimension();
  msg.is_bigendian = in.ConsumeBool();
  const int fields = in.ConsumeIntegralInRange(0, 6);
  for (int k = 0; k < fields; ++k) {
    sensor_msgs::PointField f;
    f.name = kNames[in.ConsumeIntegralInRange(0, 5)];
    f.offset = dimension();
    f.datatype = in.ConsumeIntegralInRange<std::uint8_t>(0, 9);
    f.count = in.ConsumeIntegralInRange<std::uint32_t>(0, 2);
    msg.fields.push_back(f);
  }
  const std::string data = in.ConsumeRemainingBytesAsString();
  msg.data.assign(data.begin(), data.end());
  return msg;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  FuzzedDataProvider in(data, size);
  const sensor_msgs::PointCloud2 msg = message(in);
  try {
    const auto cloud = grid_puzzle_localization::fromMsg(msg);
    // An accepted message has one point per width x height cell.
    if (cloud.size() != static_cast<std::size_t>(msg.width) * msg.height) std::abort();
    const auto times = grid_puzzle_localization::timesFromMsg(msg, "time");
    if (times && times->size() != cloud.size()) std::abort();
  } catch (const std::invalid_argument&) {
  }
  return 0;
}
