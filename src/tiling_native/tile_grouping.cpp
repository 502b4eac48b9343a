// Grouping a chunk of PCD records by tile: a counting sort over the chunk's dense range of tiles
// (a stable index sort when that range is too sparse), then each tile's bounds from its sorted records.
#include "tile_grouping.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <type_traits>
#include <vector>

namespace {

constexpr double kMaxTileIndex = 4611686018427387904.0;  // 2^62: tile indices and their spans fit int64
constexpr std::int64_t kSparseBins = 65536;              // counting sort while bins <= n + this

template <class T>
double load(const std::uint8_t* p) {
  T value;
  std::memcpy(&value, p, sizeof value);
  return static_cast<double>(value);
}

/// Reads a coordinate of any PCD numeric type.
struct AnyType {
  const std::int32_t* types;
  double operator()(const std::uint8_t* p, int axis) const {
    switch (types[axis]) {
      case kGpmF4:
        return load<float>(p);
      case kGpmF8:
        return load<double>(p);
      case kGpmI1:
        return load<std::int8_t>(p);
      case kGpmI2:
        return load<std::int16_t>(p);
      case kGpmI4:
        return load<std::int32_t>(p);
      case kGpmI8:
        return load<std::int64_t>(p);
      case kGpmU1:
        return load<std::uint8_t>(p);
      case kGpmU2:
        return load<std::uint16_t>(p);
      case kGpmU4:
        return load<std::uint32_t>(p);
      default:
        return load<std::uint64_t>(p);
    }
  }
};

/// Reads coordinates that all have type T (the usual float or double maps, without a switch per value).
template <class T>
struct OneType {
  double operator()(const std::uint8_t* p, int) const { return load<T>(p); }
};

/// floor(v / s) as numpy computes it in float64; false when it does not fit kMaxTileIndex.
bool tileIndex(double v, double s, std::int64_t* index) {
  const double q = v / s;
  if (!(std::fabs(q) < kMaxTileIndex)) return false;
  const auto truncated = static_cast<std::int64_t>(q);
  *index = q < static_cast<double>(truncated) ? truncated - 1 : truncated;
  return true;
}

class Grouping {
 public:
  Grouping(const std::uint8_t* records, std::int64_t n, std::int64_t record_bytes, const std::int64_t* offsets,
           double s, std::uint8_t* sorted, GpmTileGroup* groups, std::int64_t* scratch)
      : in_(records),
        n_(n),
        rec_(record_bytes),
        off_(offsets),
        s_(s),
        out_(sorted),
        groups_(groups),
        ti_(scratch),
        tj_(scratch + n) {}

  template <class Load>
  std::int64_t run(Load load) {
    std::int64_t i_min = std::numeric_limits<std::int64_t>::max(), i_max = std::numeric_limits<std::int64_t>::min();
    std::int64_t j_min = i_min, j_max = i_max;
    for (std::int64_t k = 0; k < n_; ++k) {
      const std::uint8_t* p = in_ + k * rec_;
      if (!tileIndex(load(p + off_[0], 0), s_, &ti_[k]) || !tileIndex(load(p + off_[1], 1), s_, &tj_[k])) return -1;
      i_min = std::min(i_min, ti_[k]);
      i_max = std::max(i_max, ti_[k]);
      j_min = std::min(j_min, tj_[k]);
      j_max = std::max(j_max, tj_[k]);
    }
    const auto span_i = static_cast<std::uint64_t>(i_max - i_min) + 1;
    const auto span_j = static_cast<std::uint64_t>(j_max - j_min) + 1;
    const auto bins_allowed = static_cast<std::uint64_t>(n_ + kSparseBins);
    const std::int64_t tiles = span_i <= bins_allowed && span_j <= bins_allowed / span_i
                                   ? countingSort(i_min, j_min, span_i * span_j, span_j)
                                   : indexSort();
    for (std::int64_t t = 0; t < tiles; ++t) setBounds(groups_[t], load);
    return tiles;
  }

 private:
  /// Dense tile keys (i - i_min) * span_j + (j - j_min): count per key, then place each record after
  /// the earlier records of its key.
  std::int64_t countingSort(std::int64_t i_min, std::int64_t j_min, std::uint64_t bins, std::uint64_t span_j) {
    std::int64_t* key = ti_;
    std::vector<std::int64_t> next(bins, 0);  // records per key, then where its next record goes
    for (std::int64_t k = 0; k < n_; ++k) {
      key[k] = (ti_[k] - i_min) * static_cast<std::int64_t>(span_j) + (tj_[k] - j_min);
      ++next[key[k]];
    }
    std::int64_t tiles = 0, start = 0;
    for (std::uint64_t b = 0; b < bins; ++b) {
      if (next[b] == 0) continue;
      const std::int64_t count = next[b];
      groups_[tiles++] = GpmTileGroup{i_min + static_cast<std::int64_t>(b / span_j),
                                      j_min + static_cast<std::int64_t>(b % span_j),
                                      0,
                                      start,
                                      count,
                                      {},
                                      {}};
      next[b] = start;
      start += count;
    }
    const auto scatter = [&](auto size) {
      for (std::int64_t k = 0; k < n_; ++k) std::memcpy(out_ + next[key[k]]++ * size, in_ + k * size, size);
    };
    switch (rec_) {  // a copy of known size compiles to a few moves
      case 12:
        scatter(std::integral_constant<std::int64_t, 12>{});
        break;
      case 16:
        scatter(std::integral_constant<std::int64_t, 16>{});
        break;
      case 32:
        scatter(std::integral_constant<std::int64_t, 32>{});
        break;
      default:
        scatter(rec_);
    }
    return tiles;
  }

  /// For tile ranges too wide for one bin per tile: a stable sort of record numbers by (i, j).
  std::int64_t indexSort() {
    std::vector<std::int64_t> order(n_);
    std::iota(order.begin(), order.end(), 0);
    std::stable_sort(order.begin(), order.end(), [this](std::int64_t a, std::int64_t b) {
      return ti_[a] != ti_[b] ? ti_[a] < ti_[b] : tj_[a] < tj_[b];
    });
    std::int64_t tiles = 0;
    for (std::int64_t q = 0; q < n_; ++q) {
      const std::int64_t k = order[q];
      std::memcpy(out_ + q * rec_, in_ + k * rec_, rec_);
      if (q == 0 || ti_[k] != ti_[order[q - 1]] || tj_[k] != tj_[order[q - 1]]) {
        groups_[tiles++] = GpmTileGroup{ti_[k], tj_[k], 0, q, 0, {}, {}};
      }
      ++groups_[tiles - 1].count;
    }
    return tiles;
  }

  template <class Load>
  void setBounds(GpmTileGroup& group, Load load) const {
    constexpr double kInf = std::numeric_limits<double>::infinity();
    double x0 = kInf, y0 = kInf, z0 = kInf, x1 = -kInf, y1 = -kInf, z1 = -kInf;
    const std::uint8_t* p = out_ + group.start * rec_;
    for (std::int64_t q = 0; q < group.count; ++q, p += rec_) {
      const double x = load(p + off_[0], 0), y = load(p + off_[1], 1), z = load(p + off_[2], 2);
      x0 = std::min(x0, x);
      x1 = std::max(x1, x);
      y0 = std::min(y0, y);
      y1 = std::max(y1, y);
      z0 = std::min(z0, z);
      z1 = std::max(z1, z);
    }
    group.min[0] = x0;
    group.min[1] = y0;
    group.min[2] = z0;
    group.max[0] = x1;
    group.max[1] = y1;
    group.max[2] = z1;
  }

  const std::uint8_t* in_;
  std::int64_t n_, rec_;
  const std::int64_t* off_;
  double s_;
  std::uint8_t* out_;
  GpmTileGroup* groups_;
  std::int64_t* ti_;  // per record: tile i (then its dense key), and tile j
  std::int64_t* tj_;
};

}  // namespace

extern "C" std::int64_t gpm_group_by_tile(const std::uint8_t* records, std::int64_t n, std::int64_t record_bytes,
                                          const std::int64_t* offsets, const std::int32_t* types, double s,
                                          std::uint8_t* sorted, GpmTileGroup* groups, std::int64_t* scratch) {
  if (n <= 0) return 0;
  Grouping grouping(records, n, record_bytes, offsets, s, sorted, groups, scratch);
  if (types[0] == types[1] && types[1] == types[2]) {
    if (types[0] == kGpmF4) return grouping.run(OneType<float>{});
    if (types[0] == kGpmF8) return grouping.run(OneType<double>{});
  }
  return grouping.run(AnyType{types});
}
