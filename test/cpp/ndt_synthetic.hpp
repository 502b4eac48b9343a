// Synthetic structured scenes for the NDT tests and benchmark: a ground plane, boxes and poles with noise.
#pragma once

#include <Eigen/Geometry>
#include <cmath>
#include <random>

#include "grid_puzzle_localization/point_cloud.hpp"

namespace grid_puzzle_localization {
namespace synthetic {

/// Samples the same surfaces for every seed (the scene layout is fixed by `layout_seed`), so two calls with different
/// `seed` give two independent scans of one world. Points in metres, world frame.
inline PointCloud scene(unsigned seed, double noise, int points = 20000, double half_extent = 15.0,
                        unsigned layout_seed = 7) {
  std::mt19937 layout(layout_seed), rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> n(0.0, noise);
  struct Box {
    Eigen::Vector3d lo, hi;
  };
  struct Pole {
    Eigen::Vector2d c;
    double r, h;
  };
  std::vector<Box> boxes;
  std::vector<Pole> poles;
  for (int i = 0; i < 6; ++i) {
    const Eigen::Vector3d c(-half_extent + 2 * half_extent * u(layout), -half_extent + 2 * half_extent * u(layout), 0);
    const Eigen::Vector3d s(1.5 + 4 * u(layout), 1.5 + 4 * u(layout), 1.5 + 3 * u(layout));
    boxes.push_back({c - Eigen::Vector3d(s.x() / 2, s.y() / 2, 0), c + Eigen::Vector3d(s.x() / 2, s.y() / 2, s.z())});
  }
  for (int i = 0; i < 8; ++i)
    poles.push_back(
        {Eigen::Vector2d(-half_extent + 2 * half_extent * u(layout), -half_extent + 2 * half_extent * u(layout)),
         0.1 + 0.1 * u(layout), 3.0 + 2 * u(layout)});
  PointCloud cloud;
  cloud.reserve(points);
  for (int i = 0; i < points; ++i) {
    const double pick = u(rng);
    Eigen::Vector3d p;
    if (pick < 0.4) {  // ground with a gentle slope, so z is not constant
      const double x = -half_extent + 2 * half_extent * u(rng), y = -half_extent + 2 * half_extent * u(rng);
      p = {x, y, 0.02 * x - 0.01 * y};
    } else if (pick < 0.85) {  // box faces (four sides and the roof)
      const Box& b = boxes[static_cast<std::size_t>(u(rng) * boxes.size()) % boxes.size()];
      const int face = static_cast<int>(u(rng) * 5) % 5;
      const Eigen::Vector3d r(u(rng), u(rng), u(rng));
      p = b.lo + (b.hi - b.lo).cwiseProduct(r);
      if (face < 4) {
        const int axis = face / 2;
        p(axis) = face % 2 ? b.hi(axis) : b.lo(axis);
      } else {
        p.z() = b.hi.z();
      }
    } else {  // poles
      const Pole& q = poles[static_cast<std::size_t>(u(rng) * poles.size()) % poles.size()];
      const double a = 2 * M_PI * u(rng);
      p = {q.c.x() + q.r * std::cos(a), q.c.y() + q.r * std::sin(a), q.h * u(rng)};
    }
    p += Eigen::Vector3d(n(rng), n(rng), n(rng));
    cloud.push_back(p.cast<float>());
  }
  return cloud;
}

/// Applies a rigid transform to every point.
inline PointCloud transformed(const PointCloud& cloud, const Eigen::Matrix4d& T) {
  PointCloud out;
  out.reserve(cloud.size());
  for (const auto& p : cloud)
    out.push_back((T.topLeftCorner<3, 3>() * p.cast<double>() + T.topRightCorner<3, 1>()).cast<float>());
  return out;
}

/// Translation error [m] and rotation error [deg] between two transforms.
inline std::pair<double, double> poseError(const Eigen::Matrix4d& a, const Eigen::Matrix4d& b) {
  const Eigen::Matrix4d d = a.inverse() * b;
  // atan2 of sine and cosine: acos of the cosine alone loses small angles to the round-off of float matrices.
  const Eigen::Matrix3d R = d.topLeftCorner<3, 3>();
  const double s = 0.5 * Eigen::Vector3d(R(2, 1) - R(1, 2), R(0, 2) - R(2, 0), R(1, 0) - R(0, 1)).norm();
  const double c = (R.trace() - 1.0) / 2.0;
  return {d.topRightCorner<3, 1>().norm(), std::atan2(s, c) * 180.0 / M_PI};
}

}  // namespace synthetic
}  // namespace grid_puzzle_localization
