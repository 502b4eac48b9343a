#include "localizer_params.hpp"

#include <ros/console.h>

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace grid_puzzle_localization {
namespace {

template <class T>
std::string text(const T& v) {
  std::ostringstream s;
  s << std::boolalpha << v;
  return s.str();
}

// Reads one parameter into `field`; if the whole config no longer validates, the default is kept.
// The config validates before each call, so a new problem is this parameter's.
class CheckedLoader {
 public:
  CheckedLoader(const ros::NodeHandle& pnh, LocalizerConfig& config, std::string log_name)
      : pnh_(pnh), config_(config), log_name_(std::move(log_name)) {}

  template <class T>
  void operator()(const std::string& name, T& field) {
    T value;
    if (!pnh_.getParam(name, value)) return;
    const T fallback = field;
    field = value;
    std::string problem = config_.validate();
    if (problem.empty()) return;
    while (!problem.empty() && (problem.back() == ' ' || problem.back() == ';')) problem.pop_back();
    field = fallback;
    ROS_WARN("%s: parameter ~%s = %s is out of range (%s); using the default %s instead", log_name_.c_str(),
             name.c_str(), text(value).c_str(), problem.c_str(), text(fallback).c_str());
  }

 private:
  const ros::NodeHandle& pnh_;
  LocalizerConfig& config_;
  std::string log_name_;
};

}  // namespace

LocalizerRosParams loadLocalizerParams(const ros::NodeHandle& pnh, const std::string& log_name) {
  LocalizerRosParams p;
  LocalizerConfig& c = p.core;
  CheckedLoader load(pnh, c, log_name);
  // max before min: a larger min_range is then checked against the final max_range.
  load("preprocess/max_range", c.preprocess.max_range);
  load("preprocess/min_range", c.preprocess.min_range);
  load("preprocess/voxel_size", c.preprocess.voxel_size);
  load("preprocess/deskew", c.preprocess.deskew);
  load("preprocess/deskew_twist_smoothing", c.deskew_twist_smoothing);
  load("recovery/after_rejections", c.recovery.after_rejections);
  load("recovery/radius", c.recovery.radius);
  load("recovery/step", c.recovery.step);
  load("recovery/candidates_per_scan", c.recovery.candidates_per_scan);
  pnh.param("preprocess/time_field", p.time_field, p.time_field);
  load("ndt/resolution", c.ndt.resolution);
  load("ndt/min_points_per_voxel", c.ndt.min_points_per_voxel);
  load("ndt/eigenvalue_ratio", c.ndt.eigenvalue_ratio);
  load("ndt/threads", c.ndt.threads);
  load("ndt/step_size", c.ndt.step_size);
  load("ndt/transformation_epsilon", c.ndt.transformation_epsilon);
  load("ndt/max_iterations", c.ndt.max_iterations);
  load("ndt/outlier_ratio", c.ndt.outlier_ratio);
  load("ndt/line_search", c.ndt.line_search);
  std::string search;
  if (pnh.getParam("ndt/search_method", search) && !parseSearchMethod(search, &c.ndt.search))
    throw std::invalid_argument("~ndt/search_method '" + search +
                                "' is unknown; use DIRECT1, DIRECT7, DIRECT27 or RADIUS");
  load("map_update_threads", c.map_update_threads);
  load("match/min_nvtl", c.min_nvtl);
  load("match/min_transformation_probability", c.min_transformation_probability);
  load("match/require_converged", c.require_converged);
  load("covariance/scale", c.covariance.scale);
  load("covariance/min_translation_std", c.covariance.min_translation_std);
  load("covariance/min_rotation_std", c.covariance.min_rotation_std);
  load("covariance/max_translation_std", c.covariance.max_translation_std);
  load("covariance/max_rotation_std", c.covariance.max_rotation_std);
  load("imu/use_gyro", c.use_gyro);
  load("imu/max_gap", c.gyro_max_gap);
  load("time_jump_back", c.time_jump_back);

  pnh.getParam("map_source", p.map_source);
  if (p.map_source != "cloud" && p.map_source != "tiles" && p.map_source != "pcd")
    throw std::invalid_argument("~map_source '" + p.map_source + "' is unknown; use cloud, tiles or pcd");
  pnh.getParam("pcd_path", p.pcd_path);
  if (p.map_source == "pcd" && p.pcd_path.empty())
    throw std::invalid_argument("~map_source is pcd but ~pcd_path is empty; set it to the global map's PCD file");
  pnh.getParam("map_frame", p.map_frame);
  pnh.getParam("odom_frame", p.odom_frame);
  pnh.getParam("base_frame", p.base_frame);
  pnh.getParam("publish_tf", p.publish_tf);
  pnh.getParam("publish_aligned_points", p.publish_aligned_points);
  pnh.getParam("resend_service", p.resend_service);
  double cache_mb = p.tile_cache_mb;
  if (pnh.getParam("tiles/cache_mb", cache_mb)) {
    if (cache_mb >= 0.0)
      p.tile_cache_mb = cache_mb;
    else
      ROS_WARN("%s: parameter ~tiles/cache_mb = %g must be >= 0 MiB; using the default %g instead", log_name.c_str(),
               cache_mb, p.tile_cache_mb);
  }
  c.output_aligned = p.publish_aligned_points;

  std::vector<double> pose;
  if (pnh.getParam("initial_pose", pose) && !pose.empty()) {
    bool finite = pose.size() == 6;
    for (double v : pose) finite = finite && std::isfinite(v);
    if (!finite)
      throw std::invalid_argument("~initial_pose must be 6 finite numbers [x y z roll pitch yaw] (m, rad) or []");
    Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
    t.translation() << pose[0], pose[1], pose[2];
    t.linear() =
        (Eigen::AngleAxisd(pose[5], Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pose[4], Eigen::Vector3d::UnitY()) *
         Eigen::AngleAxisd(pose[3], Eigen::Vector3d::UnitX()))
            .toRotationMatrix();
    p.initial_pose = t;
  }
  return p;
}

}  // namespace grid_puzzle_localization
