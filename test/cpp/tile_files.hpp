// Test and benchmark helper: a world cut into tile files named like `gpm tile`'s (<cx>_<cy>.pcd, centre in m),
// written as binary PCD x y z float32.
#pragma once

#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <stdexcept>
#include <string>

#include "grid_puzzle_localization/point_cloud.hpp"

namespace grid_puzzle_localization::test {

/// File stem of tile (i, j) of side s: its centre, one decimal (every side used here is a multiple of 0.2 m).
inline std::string tileStem(long i, long j, double s) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.1f_%.1f", (i + 0.5) * s, (j + 0.5) * s);
  return buf;
}

/// The world cut into tiles of side s (i = floor(x / s), the tiler's rule), keyed by stem, points in input order.
inline std::map<std::string, PointCloud> cutTileStems(const PointCloud& world, double s) {
  std::map<std::string, PointCloud> tiles;
  for (const Point& p : world)
    tiles[tileStem(static_cast<long>(std::floor(p.x() / s)), static_cast<long>(std::floor(p.y() / s)), s)].push_back(p);
  return tiles;
}

inline void writeBinaryPcd(const std::string& path, const PointCloud& cloud) {
  std::ofstream out(path, std::ios::binary);
  out << "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH " << cloud.size()
      << "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " << cloud.size() << "\nDATA binary\n";
  for (const Point& p : cloud) out.write(reinterpret_cast<const char*>(p.data()), 3 * sizeof(float));
  if (!out) throw std::runtime_error("cannot write " + path);
}

inline void writeTiles(const std::string& dir, const std::map<std::string, PointCloud>& tiles) {
  for (const auto& [stem, cloud] : tiles) writeBinaryPcd(dir + "/" + stem + ".pcd", cloud);
}

}  // namespace grid_puzzle_localization::test
