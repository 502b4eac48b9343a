#include "point_cloud_msg.hpp"

#include <cstring>
#include <stdexcept>

namespace grid_puzzle_localization {
namespace {

const sensor_msgs::PointField* findField(const sensor_msgs::PointCloud2& msg, const std::string& name) {
  for (const auto& f : msg.fields)
    if (f.name == name) return &f;
  return nullptr;
}

double readScalar(const std::uint8_t* src, std::uint8_t datatype) {
  if (datatype == sensor_msgs::PointField::FLOAT32) {
    float v;
    std::memcpy(&v, src, sizeof v);
    return v;
  }
  if (datatype == sensor_msgs::PointField::UINT32) {
    std::uint32_t v;
    std::memcpy(&v, src, sizeof v);
    return v;
  }
  double v;
  std::memcpy(&v, src, sizeof v);
  return v;
}

std::size_t scalarBytes(std::uint8_t datatype) { return datatype == sensor_msgs::PointField::FLOAT64 ? 8 : 4; }

// `field` is one readScalar reads (FLOAT32, FLOAT64 or UINT32): it must lie inside each point record, so that
// the data size check below bounds every read (and the point count by the buffer's length).
void checkLayout(const sensor_msgs::PointCloud2& msg, const sensor_msgs::PointField& field) {
  if (msg.is_bigendian) throw std::invalid_argument("big-endian PointCloud2 is not supported");
  if (static_cast<std::size_t>(field.offset) + scalarBytes(field.datatype) > msg.point_step)
    throw std::invalid_argument("PointCloud2 field '" + field.name + "' at offset " + std::to_string(field.offset) +
                                " does not fit in point_step " + std::to_string(msg.point_step));
  if (msg.row_step < static_cast<std::size_t>(msg.width) * msg.point_step ||
      msg.data.size() < static_cast<std::size_t>(msg.row_step) * msg.height)
    throw std::invalid_argument("PointCloud2 data is shorter than width * height * point_step");
}

// Calls visit(pointer to the point's first byte) for every point, row by row.
template <class Visit>
void forEachPoint(const sensor_msgs::PointCloud2& msg, Visit&& visit) {
  if (msg.width == 0) return;  // no points, however many (empty) rows the header claims
  for (std::uint32_t row = 0; row < msg.height; ++row) {
    const std::uint8_t* base = msg.data.data() + static_cast<std::size_t>(row) * msg.row_step;
    for (std::uint32_t col = 0; col < msg.width; ++col) visit(base + static_cast<std::size_t>(col) * msg.point_step);
  }
}

}  // namespace

PointCloud fromMsg(const sensor_msgs::PointCloud2& msg) {
  const sensor_msgs::PointField* fields[3] = {findField(msg, "x"), findField(msg, "y"), findField(msg, "z")};
  for (const auto* f : fields) {
    if (!f) throw std::invalid_argument("PointCloud2 has no x, y or z field; fields must include x y z");
    if (f->datatype != sensor_msgs::PointField::FLOAT32 && f->datatype != sensor_msgs::PointField::FLOAT64)
      throw std::invalid_argument("PointCloud2 field '" + f->name + "' must be FLOAT32 or FLOAT64");
  }
  for (const auto* f : fields) checkLayout(msg, *f);
  PointCloud cloud;
  cloud.reserve(static_cast<std::size_t>(msg.width) * msg.height);
  forEachPoint(msg, [&](const std::uint8_t* p) {
    cloud.emplace_back(static_cast<float>(readScalar(p + fields[0]->offset, fields[0]->datatype)),
                       static_cast<float>(readScalar(p + fields[1]->offset, fields[1]->datatype)),
                       static_cast<float>(readScalar(p + fields[2]->offset, fields[2]->datatype)));
  });
  return cloud;
}

std::optional<PointTimes> timesFromMsg(const sensor_msgs::PointCloud2& msg, const std::string& name) {
  const sensor_msgs::PointField* f = findField(msg, name);
  if (!f) return std::nullopt;
  double scale = 1.0;
  if (f->datatype == sensor_msgs::PointField::UINT32)
    scale = 1e-9;  // Ouster: nanoseconds after the stamp
  else if (f->datatype != sensor_msgs::PointField::FLOAT32 && f->datatype != sensor_msgs::PointField::FLOAT64)
    throw std::invalid_argument("PointCloud2 time field '" + name +
                                "' must be FLOAT32/FLOAT64 seconds or UINT32 nanoseconds after header.stamp");
  checkLayout(msg, *f);
  PointTimes times;
  times.reserve(static_cast<std::size_t>(msg.width) * msg.height);
  forEachPoint(msg, [&](const std::uint8_t* p) {
    times.push_back(static_cast<float>(scale * readScalar(p + f->offset, f->datatype)));
  });
  return times;
}

sensor_msgs::PointCloud2 toMsg(const PointCloud& cloud, const std_msgs::Header& header) {
  sensor_msgs::PointCloud2 msg;
  msg.header = header;
  msg.height = 1;
  msg.width = static_cast<std::uint32_t>(cloud.size());
  const char* names[3] = {"x", "y", "z"};
  for (std::uint32_t i = 0; i < 3; ++i) {
    sensor_msgs::PointField f;
    f.name = names[i];
    f.offset = 4 * i;
    f.datatype = sensor_msgs::PointField::FLOAT32;
    f.count = 1;
    msg.fields.push_back(f);
  }
  msg.is_bigendian = false;
  msg.point_step = 12;
  msg.row_step = msg.point_step * msg.width;
  msg.is_dense = true;
  msg.data.resize(static_cast<std::size_t>(msg.row_step));
  for (std::size_t i = 0; i < cloud.size(); ++i) std::memcpy(msg.data.data() + 12 * i, cloud[i].data(), 12);
  return msg;
}

}  // namespace grid_puzzle_localization
