#include "grid_puzzle_localization/pcd_reader.hpp"

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <sstream>
#include <vector>

namespace grid_puzzle_localization {
namespace {

struct Field {
  std::string name;
  int size = 4;
  char type = 'F';
  int count = 1;
  std::size_t offset = 0;  // bytes from the start of a binary point record
};

struct Header {
  std::vector<Field> fields;
  std::size_t points = 0;
  std::size_t point_step = 0;
  std::string data;
  std::size_t data_offset = 0;  // bytes from the start of the file
};

[[noreturn]] void fail(const std::string& path, const std::string& what) {
  throw PcdReadError("PCD file '" + path + "': " + what);
}

std::vector<std::string> words(const std::string& line) {
  std::istringstream in(line);
  return {std::istream_iterator<std::string>(in), std::istream_iterator<std::string>()};
}

Header parseHeader(const std::string& path, const std::string& bytes) {
  Header h;
  std::size_t pos = 0;
  std::vector<std::string> sizes, types, counts;
  bool have_points = false;
  std::size_t width = 0, height = 1;
  while (pos < bytes.size()) {
    const std::size_t end = bytes.find('\n', pos);
    if (end == std::string::npos) fail(path, "the header ends before a DATA line");
    const std::string line = bytes.substr(pos, end - pos);
    pos = end + 1;
    const auto w = words(line);
    if (w.empty() || w[0][0] == '#') continue;
    const std::string key = w[0];
    const std::vector<std::string> rest(w.begin() + 1, w.end());
    try {
      if (key == "FIELDS") {
        for (const auto& n : rest) h.fields.push_back({n});
      } else if (key == "SIZE") {
        sizes = rest;
      } else if (key == "TYPE") {
        types = rest;
      } else if (key == "COUNT") {
        counts = rest;
      } else if (key == "WIDTH") {
        width = std::stoul(rest.at(0));
      } else if (key == "HEIGHT") {
        height = std::stoul(rest.at(0));
      } else if (key == "POINTS") {
        h.points = std::stoul(rest.at(0));
        have_points = true;
      } else if (key == "DATA") {
        h.data = rest.at(0);
        h.data_offset = pos;
        break;
      }
    } catch (const std::exception&) {
      fail(path, "malformed header line '" + line + "'");
    }
  }
  if (h.data.empty()) fail(path, "no DATA line in the header; is this a PCD file?");
  if (!have_points) h.points = width * height;
  if (width * height != h.points)
    fail(path, "WIDTH " + std::to_string(width) + " x HEIGHT " + std::to_string(height) + " disagrees with POINTS " +
                   std::to_string(h.points));
  if (h.fields.empty()) fail(path, "no FIELDS line in the header");
  if (sizes.size() != h.fields.size() || types.size() != h.fields.size())
    fail(path, "SIZE and TYPE must have one entry per field");
  if (!counts.empty() && counts.size() != h.fields.size()) fail(path, "COUNT must have one entry per field");
  for (std::size_t i = 0; i < h.fields.size(); ++i) {
    Field& f = h.fields[i];
    try {
      f.size = std::stoi(sizes[i]);
      f.count = counts.empty() ? 1 : std::stoi(counts[i]);
    } catch (const std::exception&) {
      fail(path, "non-numeric SIZE or COUNT for field '" + f.name + "'");
    }
    f.type = types[i].empty() ? '?' : types[i][0];
    if (f.size <= 0 || f.count <= 0 || (f.type != 'F' && f.type != 'I' && f.type != 'U'))
      fail(path, "unsupported SIZE/TYPE/COUNT for field '" + f.name + "'");
    f.offset = h.point_step;
    h.point_step += static_cast<std::size_t>(f.size) * f.count;
  }
  return h;
}

const Field& xyzField(const std::string& path, const Header& h, const std::string& name) {
  for (const Field& f : h.fields)
    if (f.name == name) {
      if (f.type != 'F' || (f.size != 4 && f.size != 8))
        fail(path, "field '" + name + "' must be float32 or float64 (TYPE F, SIZE 4 or 8)");
      return f;
    }
  fail(path, "no '" + name + "' field; the reader needs x, y and z");
}

float readFloat(const char* p, int size) {
  if (size == 4) {
    float v;
    std::memcpy(&v, p, 4);
    return v;
  }
  double v;
  std::memcpy(&v, p, 8);
  return static_cast<float>(v);
}

// LZF decompression (the format of PCL's binary_compressed): literal runs and back references.
std::vector<char> lzfDecompress(const std::string& path, const unsigned char* in, std::size_t in_len,
                                std::size_t out_len) {
  std::vector<char> out(out_len);
  std::size_t ip = 0, op = 0;
  while (ip < in_len) {
    const unsigned ctrl = in[ip++];
    if (ctrl < 32) {  // literal run of ctrl + 1 bytes
      const std::size_t len = ctrl + 1;
      if (ip + len > in_len || op + len > out_len) fail(path, "corrupt compressed data (literal run)");
      std::memcpy(out.data() + op, in + ip, len);
      ip += len;
      op += len;
    } else {  // back reference
      std::size_t len = ctrl >> 5;
      if (len == 7) {
        if (ip >= in_len) fail(path, "corrupt compressed data (length)");
        len += in[ip++];
      }
      len += 2;
      if (ip >= in_len) fail(path, "corrupt compressed data (offset)");
      const std::size_t back = ((ctrl & 0x1f) << 8) + in[ip++] + 1;
      if (back > op || op + len > out_len) fail(path, "corrupt compressed data (reference)");
      for (std::size_t k = 0; k < len; ++k, ++op) out[op] = out[op - back];  // may overlap: byte by byte
    }
  }
  if (op != out_len) fail(path, "compressed data decompresses to the wrong size");
  return out;
}

// LZF's best case: a 3-byte back reference repeats 264 bytes; a block claiming more is corrupt.
constexpr std::size_t kLzfMaxExpansion = 88;

void failTruncated(const std::string& path, const Header& h, const std::string& what) {
  fail(path, "truncated: POINTS " + std::to_string(h.points) + " needs more " + what +
                 " than the file holds; re-export or re-download it");
}

}  // namespace

// Like PCL, the reference reader: POINTS records are read and anything after them (zero padding some
// recorders leave, extra lines) is ignored; fewer records than POINTS is an error. Every count from the
// header is checked against the file's size before the cloud is allocated.
PointCloud readPcdXyz(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) fail(path, "cannot open it; check the path and permissions");
  std::string bytes;
  try {
    bytes.assign(std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>());
  } catch (const std::ios_base::failure&) {  // libstdc++ throws on a read error: a directory opens, EISDIR
    fail(path, std::string("cannot read it (") + std::strerror(errno) + "); it must be a readable PCD file");
  }
  const Header h = parseHeader(path, bytes);
  const Field* xyz[3] = {&xyzField(path, h, "x"), &xyzField(path, h, "y"), &xyzField(path, h, "z")};
  const char* data = bytes.data() + h.data_offset;
  const std::size_t avail = bytes.size() - h.data_offset;
  PointCloud cloud;
  if (h.data == "binary") {
    if (h.points > avail / h.point_step) failTruncated(path, h, "binary data");
    cloud.resize(h.points);
    for (std::size_t i = 0; i < h.points; ++i)
      for (int a = 0; a < 3; ++a) cloud[i][a] = readFloat(data + i * h.point_step + xyz[a]->offset, xyz[a]->size);
  } else if (h.data == "binary_compressed") {
    if (avail < 8) fail(path, "the compressed data block is missing its sizes");
    std::uint32_t packed = 0, unpacked = 0;
    std::memcpy(&packed, data, 4);
    std::memcpy(&unpacked, data + 4, 4);
    if (avail - 8 < packed) failTruncated(path, h, "compressed data");
    if (unpacked > kLzfMaxExpansion * static_cast<std::size_t>(packed))
      fail(path, "corrupt compressed data sizes (" + std::to_string(packed) + " LZF bytes cannot decompress to " +
                     std::to_string(unpacked) + ")");
    if (h.points > unpacked / h.point_step || unpacked != h.points * h.point_step)
      fail(path, "POINTS " + std::to_string(h.points) + " disagrees with the data: it decompresses to " +
                     std::to_string(unpacked) + " bytes, not POINTS x " + std::to_string(h.point_step));
    cloud.resize(h.points);
    const std::vector<char> raw =
        lzfDecompress(path, reinterpret_cast<const unsigned char*>(data + 8), packed, unpacked);
    // Decompressed layout is per field: all points' values of field 0, then field 1, ...
    for (int a = 0; a < 3; ++a) {
      const std::size_t base = xyz[a]->offset * h.points;
      const std::size_t stride = static_cast<std::size_t>(xyz[a]->size) * xyz[a]->count;
      for (std::size_t i = 0; i < h.points; ++i) cloud[i][a] = readFloat(raw.data() + base + i * stride, xyz[a]->size);
    }
  } else if (h.data == "ascii") {
    // Columns: each field contributes `count` values; find the column of x, y, z.
    std::size_t col[3] = {0, 0, 0}, columns = 0;
    for (const Field& f : h.fields) {
      for (int a = 0; a < 3; ++a)
        if (&f == xyz[a]) col[a] = columns;
      columns += f.count;
    }
    if (h.points > avail / (2 * columns)) failTruncated(path, h, "ascii lines");  // a value and a separator each
    cloud.resize(h.points);
    std::istringstream in(std::string(data, avail));
    std::string line;
    std::size_t i = 0;
    while (i < h.points && std::getline(in, line)) {
      const auto w = words(line);
      if (w.empty()) continue;
      if (w.size() < columns) fail(path, "ascii point " + std::to_string(i) + " has too few values");
      for (int a = 0; a < 3; ++a) {
        try {
          cloud[i][a] = std::stof(w[col[a]]);
        } catch (const std::out_of_range&) {
          cloud[i][a] = std::strtof(w[col[a]].c_str(), nullptr);  // inf / denormal: keep what strtof gives
        } catch (const std::exception&) {
          fail(path, "ascii point " + std::to_string(i) + " has a non-numeric coordinate");
        }
      }
      ++i;
    }
    if (i < h.points)
      fail(path, "ascii data holds " + std::to_string(i) + " points, POINTS says " + std::to_string(h.points));
  } else {
    fail(path, "unsupported DATA '" + h.data + "' (ascii, binary and binary_compressed are supported)");
  }
  return cloud;
}

}  // namespace grid_puzzle_localization
