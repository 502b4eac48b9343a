// Test helper: a small structured world (ground, walls, boxes, poles) as points, and scans cut from it.
#pragma once

#include <Eigen/Geometry>
#include <cmath>
#include <random>

#include "grid_puzzle_localization/point_cloud.hpp"

namespace grid_puzzle_localization::test {

inline void addPlane(PointCloud& out, const Eigen::Vector3f& origin, const Eigen::Vector3f& u, const Eigen::Vector3f& v,
                     float step) {
  const int nu = static_cast<int>(u.norm() / step);
  const int nv = static_cast<int>(v.norm() / step);
  for (int i = 0; i <= nu; ++i)
    for (int j = 0; j <= nv; ++j) out.push_back(origin + u * (float(i) / nu) + v * (float(j) / nv));
}

/// A 60 m x 40 m yard around the origin: ground, four walls, boxes and poles (map frame, metres), with
/// 1 cm Gaussian noise like a real survey (exactly planar voxels are a degenerate case of their own).
inline PointCloud makeWorld(float step = 0.2f, unsigned seed = 3) {
  PointCloud w;
  addPlane(w, {-30, -20, 0}, {60, 0, 0}, {0, 40, 0}, step);
  addPlane(w, {-30, -20, 0}, {60, 0, 0}, {0, 0, 6}, step);
  addPlane(w, {-30, 20, 0}, {60, 0, 0}, {0, 0, 4}, step);
  addPlane(w, {-30, -20, 0}, {0, 40, 0}, {0, 0, 5}, step);
  addPlane(w, {30, -20, 0}, {0, 40, 0}, {0, 0, 7}, step);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> ux(-25, 25), uy(-15, 15), us(1, 3);
  for (int b = 0; b < 12; ++b) {
    const Eigen::Vector3f c(ux(rng), uy(rng), 0);
    const float sx = us(rng), sy = us(rng), sz = us(rng);
    addPlane(w, c, {sx, 0, 0}, {0, 0, sz}, step);
    addPlane(w, c + Eigen::Vector3f(0, sy, 0), {sx, 0, 0}, {0, 0, sz}, step);
    addPlane(w, c, {0, sy, 0}, {0, 0, sz}, step);
    addPlane(w, c + Eigen::Vector3f(sx, 0, 0), {0, sy, 0}, {0, 0, sz}, step);
    addPlane(w, c + Eigen::Vector3f(0, 0, sz), {sx, 0, 0}, {0, sy, 0}, step);
  }
  for (int p = 0; p < 10; ++p) {
    const Eigen::Vector3f c(ux(rng), uy(rng), 0);
    for (float z = 0; z < 5; z += step)
      for (int a = 0; a < 12; ++a)
        w.push_back(c + Eigen::Vector3f(0.2f * std::cos(a * 0.5236f), 0.2f * std::sin(a * 0.5236f), z));
  }
  std::normal_distribution<float> noise(0.0f, 0.01f);
  for (Point& p : w) p += Point(noise(rng), noise(rng), noise(rng));
  return w;
}

/// The world points within `range` of the sensor at map_T_sensor, in the sensor frame, with Gaussian noise.
inline PointCloud scanFrom(const PointCloud& world, const Eigen::Isometry3d& map_T_sensor, float range, float noise,
                           unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> n(0.0f, noise);
  const Eigen::Isometry3f sensor_T_map = map_T_sensor.inverse().cast<float>();
  PointCloud out;
  for (const Point& p : world) {
    const Point q = sensor_T_map * p;
    if (q.norm() < range) out.push_back(q + Point(n(rng), n(rng), n(rng)));
  }
  return out;
}

inline Eigen::Isometry3d poseXYYaw(double x, double y, double yaw, double z = 0.0) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.translation() << x, y, z;
  t.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return t;
}

inline double translationError(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return (a.translation() - b.translation()).norm();
}

inline double rotationError(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return Eigen::AngleAxisd(a.rotation().transpose() * b.rotation()).angle();
}

}  // namespace grid_puzzle_localization::test

#include <map>
#include <string>

namespace grid_puzzle_localization::test {

/// The world cut into square tiles of side `s` [m], keyed "i_j" with i = floor(x / s), j = floor(y / s).
inline std::map<std::string, PointCloud> cutTiles(const PointCloud& world, float s) {
  std::map<std::string, PointCloud> tiles;
  for (const Point& p : world) {
    const int i = static_cast<int>(std::floor(p.x() / s));
    const int j = static_cast<int>(std::floor(p.y() / s));
    tiles[std::to_string(i) + "_" + std::to_string(j)].push_back(p);
  }
  return tiles;
}

}  // namespace grid_puzzle_localization::test
