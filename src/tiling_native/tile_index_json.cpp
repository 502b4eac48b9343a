// Formatting the tiles array of index.json; floats as Python's repr writes them, so the text is what
// json.dumps would write.
#include "tile_index_json.hpp"

#include <algorithm>
#include <charconv>
#include <cstdlib>  // std::abs
#include <cstring>

namespace {

/// Appends text to a buffer of fixed capacity, remembering whether it overflowed.
class Text {
 public:
  Text(char* out, std::int64_t capacity) : out_(out), capacity_(capacity) {}

  void put(const char* text, std::size_t size) {
    if (overflow_ || size > static_cast<std::size_t>(capacity_ - size_)) {
      overflow_ = true;
      return;
    }
    std::memcpy(out_ + size_, text, size);
    size_ += static_cast<std::int64_t>(size);
  }
  void put(const char* text) { put(text, std::strlen(text)); }

  void putInt(std::int64_t value) {
    char digits[24];
    const auto result = std::to_chars(digits, digits + sizeof digits, value);
    put(digits, static_cast<std::size_t>(result.ptr - digits));
  }

  /// Python's repr of a finite double: the shortest digits that read back as `value`, in fixed
  /// notation when the decimal point falls within 16 digits left or 4 right of them (".0" when there
  /// is no fraction), otherwise as d.ddde+XX.
  void putFloat(double value) {
    char scientific[40];
    const char* end =
        std::to_chars(scientific, scientific + sizeof scientific, value, std::chars_format::scientific).ptr;
    const char* p = scientific;
    char out[48];
    char* o = out;
    if (*p == '-') *o++ = *p++;
    char digits[24];
    int count = 0;
    for (; p < end && *p != 'e'; ++p) {
      if (*p != '.') digits[count++] = *p;
    }
    const char* exponent_text = p + 1;  // after the 'e': a sign, then digits
    if (*exponent_text == '+') ++exponent_text;
    int point = 0;
    std::from_chars(exponent_text, end, point);
    ++point;  // value = 0.digits * 10^point
    const auto copy = [&o](const char* from, int n) { o = std::copy(from, from + n, o); };
    if (point > -4 && point <= 16) {
      if (point <= 0) {
        copy("0.000", 2 - point);
        copy(digits, count);
      } else if (point >= count) {
        copy(digits, count);
        o = std::fill_n(o, point - count, '0');
        copy(".0", 2);
      } else {
        copy(digits, point);
        *o++ = '.';
        copy(digits + point, count - point);
      }
    } else {
      *o++ = digits[0];
      if (count > 1) {
        *o++ = '.';
        copy(digits + 1, count - 1);
      }
      const int exponent = point - 1;
      copy(exponent < 0 ? "e-0" : "e+0", std::abs(exponent) < 10 ? 3 : 2);
      o = std::to_chars(o, out + sizeof out, std::abs(exponent)).ptr;
    }
    put(out, static_cast<std::size_t>(o - out));
  }

  bool overflow() const { return overflow_; }
  std::int64_t size() const { return size_; }

 private:
  char* out_;
  std::int64_t capacity_;
  std::int64_t size_ = 0;
  bool overflow_ = false;
};

}  // namespace

extern "C" std::int64_t gpm_tiles_json(std::int64_t tiles, const GpmTileColumns* columns, double grid_size,
                                       std::int64_t record_bytes, char* out, std::int64_t capacity) {
  Text text(out, capacity);
  const char* file = columns->files;
  for (std::int64_t t = 0; t < tiles && !text.overflow(); ++t) {
    const std::size_t file_size = std::strlen(file);
    const std::size_t stem_size = file_size >= 4 ? file_size - 4 : 0;  // without ".pcd"
    text.put(t == 0 ? "{\"key\":[" : ",{\"key\":[");
    text.putInt(columns->i[t]);
    text.put(",");
    text.putInt(columns->j[t]);
    text.put("],\"stem\":\"");
    text.put(file, stem_size);
    text.put("\",\"file\":\"");
    text.put(file, file_size);
    text.put("\",\"center\":[");
    text.putFloat((static_cast<double>(columns->i[t]) + 0.5) * grid_size);
    text.put(",");
    text.putFloat((static_cast<double>(columns->j[t]) + 0.5) * grid_size);
    text.put("],\"points\":");
    text.putInt(columns->points[t]);
    for (int end = 0; end < 2; ++end) {
      text.put(end == 0 ? ",\"bounds\":{\"min\":[" : "],\"max\":[");
      const double* const* bound = end == 0 ? columns->lower : columns->upper;
      for (int axis = 0; axis < 3; ++axis) {
        if (axis > 0) text.put(",");
        text.putFloat(bound[axis][t]);
      }
    }
    text.put("]},\"bytes\":");
    text.putInt(columns->bytes[t]);
    text.put(",\"data_bytes\":");
    text.putInt(columns->points[t] * record_bytes);
    text.put("}");
    file += file_size + 1;
  }
  return text.overflow() ? -1 : text.size();
}
