#include "grid_puzzle_localization/provider/tile_directory.hpp"

#include <dirent.h>
#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <nlohmann/json.hpp>
#include <stdexcept>

namespace grid_puzzle_localization {
namespace {

constexpr std::int64_t kOffset = std::int64_t{1} << 31;  // codes hold i + 2^31 and j + 2^31
constexpr std::uint64_t kLow = (std::uint64_t{1} << 32) - 1;
constexpr const char* kIndexFile = "index.json";
constexpr const char* kIndexFormat = "grid_puzzle_tiles";
constexpr std::uint64_t kIndexVersion = 1;

std::string formatFixed(long double value, int digits) {
  const int size = std::snprintf(nullptr, 0, "%.*Lf", digits, value);
  std::string text(static_cast<std::size_t>(size) + 1, '\0');
  std::snprintf(&text[0], text.size(), "%.*Lf", digits, value);
  text.resize(static_cast<std::size_t>(size));
  return text;
}

// "-?d+.d+": the number form of a tile name.
bool isTileNumber(const std::string& s, std::size_t begin, std::size_t end) {
  if (begin < end && s[begin] == '-') ++begin;
  const std::size_t dot = s.find('.', begin);
  if (dot == std::string::npos || dot >= end || dot == begin || dot + 1 == end) return false;
  for (std::size_t c = begin; c < end; ++c)
    if (c != dot && !std::isdigit(static_cast<unsigned char>(s[c]))) return false;
  return true;
}

bool isDirectory(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode);
}

bool isFile(const std::string& path) {
  struct stat st {};
  return ::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode);
}

double checkedGridSize(double s, const std::string& path) {
  if (!(std::isfinite(s) && s > 0.0))
    throw std::invalid_argument("tile directory " + path + ": grid size must be a positive number of metres (got " +
                                std::to_string(s) + "); set tiles/grid_size, e.g. 2");
  return s;
}

// Streaming reader of index.json (schema: src/grid_puzzle_localization/tiling/index.py): the header members of the
// top-level object and the "key" of every entry of its "tiles" array; nothing else is kept.
class IndexReader {
 public:
  using json = nlohmann::json;
  // The tiler writes its keys sorted: they go straight into runs. Keys out of order are collected and sorted.
  TileRuns runs;
  std::vector<std::uint64_t> unsorted;
  std::string format;
  std::uint64_t version = 0;
  double grid_size = std::nan("");
  std::string error;

  bool null() { return value(); }
  bool boolean(bool) { return value(); }
  bool number_integer(json::number_integer_t v) { return number(static_cast<long double>(v), true); }
  bool number_unsigned(json::number_unsigned_t v) { return number(static_cast<long double>(v), true); }
  bool number_float(json::number_float_t v, const json::string_t&) { return number(v, false); }
  // Set to collect every tile's file, size and checksum (parseTileIndex), not only its key.
  bool collect_entries = false;
  std::vector<TileIndexEntry> entries;

  bool string(json::string_t& v) {
    if (stack_.size() == 1 && key_ == "format") format = v;
    if (collect_entries && inTile() && key_ == "file") entry_.file = v;
    if (collect_entries && inTile() && key_ == "sha256") {
      if (!isSha256Hex(v)) return fail("a tile's sha256 '" + v.substr(0, 80) + "' is not 64 lowercase hex digits");
      entry_.sha256 = v;
    }
    return value();
  }
  template <class Binary>
  bool binary(Binary&) {
    return value();
  }
  bool start_object(std::size_t) {
    if (collect_entries && stack_.size() == 2 && in_tiles_) entry_ = TileIndexEntry();
    return open('{');
  }
  bool end_object() {
    if (collect_entries && inTile()) {
      if (entry_.file.empty()) return fail("tile " + std::to_string(entries.size()) + " has no file name");
      if (!entries.empty() && entries.front().sha256.empty() != entry_.sha256.empty())
        return fail("some tiles have a sha256 and others have none");
      entries.push_back(std::move(entry_));
    }
    return close();
  }
  bool start_array(std::size_t) {
    if (inKey()) key_values_ = 0;
    return open('[');
  }
  bool end_array() {
    if (stack_.size() == 4 && in_key_array_) {
      in_key_array_ = false;
      if (key_values_ != 2) return fail("a tile key is not [i, j]");
      try {
        const std::uint64_t code = encodeTileKey(key_i_, key_j_);
        if (!unsorted.empty() || !runs.append(key_i_, key_j_)) unsorted.push_back(code);
      } catch (const std::out_of_range& e) {
        return fail(e.what());
      }
    }
    return close();
  }
  bool key(json::string_t& k) {
    key_ = k;
    if (stack_.size() == 3 && in_tiles_) in_key_array_ = k == "key";
    return true;
  }
  template <class Exception>
  bool parse_error(std::size_t position, const std::string&, const Exception& e) {
    return fail("byte " + std::to_string(position) + ": " + e.what());
  }

 private:
  bool inKey() const { return stack_.size() == 3 && in_tiles_ && in_key_array_; }
  bool inTile() const { return stack_.size() == 3 && in_tiles_; }
  static bool isSha256Hex(const std::string& v) {
    return v.size() == 64 &&
           std::all_of(v.begin(), v.end(), [](char c) { return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'); });
  }
  bool open(char kind) {
    if (stack_.size() == 1 && kind == '[') in_tiles_ = key_ == "tiles";
    stack_.push_back(kind);
    return true;
  }
  bool close() {
    stack_.pop_back();
    if (stack_.size() == 1) in_tiles_ = false;
    return true;
  }
  bool value() { return true; }
  bool number(long double v, bool integral) {
    if (stack_.size() == 1 && key_ == "version" && integral) version = static_cast<std::uint64_t>(v);
    if (stack_.size() == 1 && key_ == "grid_size") grid_size = static_cast<double>(v);
    if (collect_entries && inTile() && key_ == "bytes") {
      if (!integral || v < 0) return fail("a tile's bytes is not a non-negative integer");
      entry_.bytes = static_cast<std::uint64_t>(v);
    }
    if (stack_.size() == 4 && in_key_array_) {
      if (!integral) return fail("a tile key holds a non-integer");
      (key_values_ == 0 ? key_i_ : key_j_) = static_cast<std::int64_t>(v);
      ++key_values_;
    }
    return true;
  }
  bool fail(const std::string& what) {
    error = what;
    return false;
  }

  std::vector<char> stack_;
  std::string key_;
  bool in_tiles_ = false, in_key_array_ = false;
  int key_values_ = 0;
  std::int64_t key_i_ = 0, key_j_ = 0;
  TileIndexEntry entry_;
};

// `runs` with the tiles of `codes` (any order; duplicates dropped).
TileRuns withCodes(TileRuns runs, std::vector<std::uint64_t> codes) {
  if (codes.empty()) return runs;
  if (!runs.empty()) runs.codesInBox(runs.bounds(), codes);
  std::sort(codes.begin(), codes.end());
  TileRuns out;
  for (const std::uint64_t c : codes) {
    const TileKey k = decodeTileKey(c);
    out.append(k.i, k.j);
  }
  return out;
}

// Why a parsed index cannot be used ("" when it can).
template <class Input>
std::string parseIndex(Input&& in, IndexReader& reader) {
  if (!nlohmann::json::sax_parse(std::forward<Input>(in), &reader))
    return reader.error.empty() ? "not JSON" : reader.error;
  if (reader.format != kIndexFormat || reader.version != kIndexVersion)
    return "not a version " + std::to_string(kIndexVersion) + " " + kIndexFormat + " index";
  if (!(std::isfinite(reader.grid_size) && reader.grid_size > 0.0)) return "no positive grid_size";
  return "";
}

std::invalid_argument unreadableIndex(const std::string& what, const std::string& problem) {
  return std::invalid_argument(what + ": not a readable tile index (" + problem + "); re-run `gpm tile`");
}

TileRuns readIndexKeys(const std::string& index_path, double& grid_size) {
  std::ifstream in(index_path, std::ios::binary);
  IndexReader reader;
  const std::string problem = in ? parseIndex(in, reader) : "cannot be opened";
  if (!problem.empty()) throw unreadableIndex(index_path, problem);
  grid_size = reader.grid_size;
  return withCodes(std::move(reader.runs), std::move(reader.unsorted));
}

void scanTiles(TileDirectory& dir) {
  DIR* d = ::opendir(dir.path.c_str());
  if (d == nullptr)
    throw std::invalid_argument("tile directory " + dir.path + " cannot be read; check its permissions");
  std::vector<std::uint64_t> codes;
  while (const dirent* entry = ::readdir(d)) {
    const std::string name = entry->d_name;
    if (name.size() < 4 || name.compare(name.size() - 4, 4, ".pcd") != 0) continue;
    TileKey key;
    if (parseTileStem(name.substr(0, name.size() - 4), dir.grid_size, key))
      codes.push_back(encodeTileKey(key.i, key.j));
    else
      dir.unparsable.push_back(name);
  }
  ::closedir(d);
  dir.tiles = withCodes(TileRuns(), std::move(codes));
  std::sort(dir.unparsable.begin(), dir.unparsable.end());
}

}  // namespace

std::uint64_t encodeTileKey(std::int64_t i, std::int64_t j) {
  if (i < -kOffset || i >= kOffset || j < -kOffset || j >= kOffset)
    throw std::out_of_range("tile index (" + std::to_string(i) + ", " + std::to_string(j) + ") is beyond +-2^31");
  return (static_cast<std::uint64_t>(i + kOffset) << 32) | static_cast<std::uint64_t>(j + kOffset);
}

TileKey decodeTileKey(std::uint64_t code) {
  return {static_cast<std::int64_t>(code >> 32) - kOffset, static_cast<std::int64_t>(code & kLow) - kOffset};
}

std::string formatTileCentre(std::int64_t i, double s) {
  const long double exact = (static_cast<long double>(i) + 0.5L) * static_cast<long double>(s);
  const long double tolerance = static_cast<long double>(s) * 1e-9L;
  const double nearest = static_cast<double>(exact);
  for (int digits = 1; digits < 18; ++digits) {
    const std::string text = formatFixed(nearest, digits);
    if (std::fabs(std::strtold(text.c_str(), nullptr) - exact) <= tolerance) return text;
  }
  return formatFixed(nearest, 17);
}

std::string tileStem(std::int64_t i, std::int64_t j, double s) {
  return formatTileCentre(i, s) + "_" + formatTileCentre(j, s);
}

bool parseTileStem(const std::string& stem, double s, TileKey& key) {
  const std::size_t sep = stem.find('_');
  if (sep == std::string::npos || !isTileNumber(stem, 0, sep) || !isTileNumber(stem, sep + 1, stem.size()))
    return false;
  const TileKey k{tileIndex(std::strtod(stem.c_str(), nullptr), s),
                  tileIndex(std::strtod(stem.c_str() + sep + 1, nullptr), s)};
  if (tileStem(k.i, k.j, s) != stem) return false;
  key = k;
  return true;
}

TileIndexListing parseTileIndex(const std::string& text, const std::string& what) {
  IndexReader reader;
  reader.collect_entries = true;
  const std::string problem = parseIndex(text, reader);
  if (!problem.empty()) throw unreadableIndex(what, problem);
  TileIndexListing listing;
  listing.grid_size = reader.grid_size;
  listing.tiles = std::move(reader.entries);
  listing.keys = withCodes(std::move(reader.runs), std::move(reader.unsorted));
  return listing;
}

std::string tileIndexRevision(const std::string& dir) {
  struct stat st {};
  if (::stat((dir + "/" + kIndexFile).c_str(), &st) == 0)
    return "index:" + std::to_string(st.st_ino) + ":" +
           std::to_string(static_cast<long long>(st.st_mtim.tv_sec) * 1000000000LL + st.st_mtim.tv_nsec) + ":" +
           std::to_string(st.st_size);
  if (::stat(dir.c_str(), &st) != 0) throw std::invalid_argument("tile directory " + dir + " cannot be read any more");
  return "scan:" + std::to_string(st.st_ino) + ":" +
         std::to_string(static_cast<long long>(st.st_mtim.tv_sec) * 1000000000LL + st.st_mtim.tv_nsec);
}

bool TileRuns::append(std::int64_t i, std::int64_t j) {
  if (!row_i_.empty() && (i < row_i_.back() || (i == row_i_.back() && j <= runs_.back().j_last))) return false;
  if (row_i_.empty() || i != row_i_.back()) {
    row_i_.push_back(i);
    row_first_.push_back(runs_.size());
    runs_.push_back({j, j});
  } else if (j == runs_.back().j_last + 1) {
    runs_.back().j_last = j;
  } else {
    runs_.push_back({j, j});
  }
  ++size_;
  return true;
}

void TileRuns::codesInBox(const TileBox& box, std::vector<std::uint64_t>& out) const {
  if (box.empty()) return;
  for (auto row = std::lower_bound(row_i_.begin(), row_i_.end(), box.i_min); row != row_i_.end() && *row <= box.i_max;
       ++row) {
    const std::size_t r = static_cast<std::size_t>(row - row_i_.begin());
    const auto first = runs_.begin() + static_cast<std::ptrdiff_t>(row_first_[r]);
    const auto end =
        r + 1 < row_first_.size() ? runs_.begin() + static_cast<std::ptrdiff_t>(row_first_[r + 1]) : runs_.end();
    // The first run that ends at or after the box's first column, then every run that starts within the box.
    auto run = std::lower_bound(first, end, box.j_min, [](const Run& a, std::int64_t j) { return a.j_last < j; });
    for (; run != end && run->j_first <= box.j_max; ++run)
      for (std::int64_t j = std::max(run->j_first, box.j_min); j <= std::min(run->j_last, box.j_max); ++j)
        out.push_back(encodeTileKey(*row, j));
  }
}

TileBox TileRuns::bounds() const {
  TileBox b{row_i_.front(), row_i_.back(), runs_.front().j_first, runs_.front().j_last};
  for (const Run& run : runs_) {
    b.j_min = std::min(b.j_min, run.j_first);
    b.j_max = std::max(b.j_max, run.j_last);
  }
  return b;
}

TileDirectory tileDirectoryOfIndex(const std::string& url, const TileIndexListing& listing, double grid_size) {
  const double s = listing.grid_size;
  if (grid_size > 0.0 && std::fabs(grid_size - s) > 1e-9 * s)
    throw std::invalid_argument("grid size " + std::to_string(grid_size) + " m disagrees with " + url +
                                "/index.json, which says " + std::to_string(s) +
                                " m; leave the grid size unset (0) to use the index's");
  if (listing.keys.empty())
    throw std::invalid_argument("tile directory " + url +
                                ": its index lists no tiles; re-run `gpm tile` on a non-empty map");
  TileDirectory dir;
  dir.path = url;
  dir.grid_size = s;
  dir.tiles = listing.keys;
  dir.source = "index";
  dir.bounds = dir.tiles.bounds();
  return dir;
}

TileDirectory openTileDirectory(const std::string& path, double grid_size) {
  if (!isDirectory(path))
    throw std::invalid_argument("tile directory " + path +
                                " does not exist; write one with `gpm tile` or fix the path");
  TileDirectory dir;
  dir.path = path;
  const std::string index = path + "/" + kIndexFile;
  if (isFile(index)) {
    double s = 0.0;
    dir.tiles = readIndexKeys(index, s);
    if (grid_size > 0.0 && std::fabs(grid_size - s) > 1e-9 * s)
      throw std::invalid_argument("grid size " + std::to_string(grid_size) + " m disagrees with " + index +
                                  ", which says " + std::to_string(s) +
                                  " m; leave the grid size unset (0) to use the index's");
    if (dir.tiles.empty())
      throw std::invalid_argument("tile directory " + path +
                                  ": its index lists no tiles; re-run `gpm tile` on a non-empty map");
    dir.grid_size = s;
    dir.source = "index";
  } else {
    if (!(grid_size > 0.0))
      throw std::invalid_argument("tile directory " + path +
                                  " has no index file, so the grid size is unknown; pass it (tiles/grid_size)");
    dir.grid_size = checkedGridSize(grid_size, path);
    dir.source = "scan";
    scanTiles(dir);
    if (dir.tiles.empty())
      throw std::invalid_argument(
          "tile directory " + path +
          " holds no tile files named <cx>_<cy>.pcd for s = " + std::to_string(dir.grid_size) + " m" +
          (dir.unparsable.empty() ? std::string()
                                  : " (" + std::to_string(dir.unparsable.size()) +
                                        " .pcd files with other names, e.g. " + dir.unparsable.front() + ")"));
  }
  dir.bounds = dir.tiles.bounds();
  return dir;
}

}  // namespace grid_puzzle_localization
