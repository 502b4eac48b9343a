#include "structure_cells.hpp"

#include <algorithm>
#include <cmath>

#include "grid_puzzle_localization/tile_geometry.hpp"

namespace grid_puzzle_localization {

GroundCells::GroundCells(const std::vector<Eigen::Vector3d>& points, double cell) : cell_(cell) {
  for (const Eigen::Vector3d& p : points) {
    auto it = lowest_.emplace(keyOf(p.x(), p.y()), p.z()).first;
    it->second = std::min(it->second, p.z());
  }
}

std::int64_t GroundCells::keyOf(double x, double y) const {
  return cellKey(static_cast<std::int64_t>(std::floor(x / cell_)), static_cast<std::int64_t>(std::floor(y / cell_)));
}

double GroundCells::lowest(double x, double y) const { return lowest_.at(keyOf(x, y)); }

bool GroundCells::visitNear(double x, double y, double radius, const std::function<bool(double)>& visit) const {
  const int r = static_cast<int>(std::ceil(radius / cell_));
  const auto cx = static_cast<std::int64_t>(std::floor(x / cell_));
  const auto cy = static_cast<std::int64_t>(std::floor(y / cell_));
  for (int dy = -r; dy <= r; ++dy)
    for (int dx = -r; dx <= r; ++dx) {
      const double ex = cellCentre(cx + dx, cell_) - x;
      const double ey = cellCentre(cy + dy, cell_) - y;
      if (ex * ex + ey * ey > radius * radius) continue;
      const auto it = lowest_.find(cellKey(cx + dx, cy + dy));
      if (it != lowest_.end() && visit(it->second)) return true;
    }
  return false;
}

bool GroundCells::heightNear(double x, double y, double radius, double* height) const {
  std::vector<double> near;
  visitNear(x, y, radius, [&near](double lowest) {
    near.push_back(lowest);
    return false;
  });
  if (near.empty()) return false;
  std::nth_element(near.begin(), near.begin() + near.size() / 2, near.end());
  *height = near[near.size() / 2];
  return true;
}

bool GroundCells::holdsNear(double x, double y, double radius) const {
  return visitNear(x, y, radius, [](double) { return true; });
}

std::vector<StructurePoint> structurePoints(const std::vector<Eigen::Vector3d>& points, const GroundCells& ground,
                                            double min_height, double max_height) {
  std::vector<StructurePoint> out;
  for (const Eigen::Vector3d& p : points) {
    const double h = p.z() - ground.lowest(p.x(), p.y());
    if (h >= min_height && h <= max_height) out.push_back({p.head<2>(), h});
  }
  return out;
}

}  // namespace grid_puzzle_localization
