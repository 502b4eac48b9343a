#include "localizer_params.hpp"

#include <cmath>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "grid_puzzle_localization/rpy.hpp"
#include "saved_pose.hpp"

namespace grid_puzzle_localization {
namespace {

template <class T>
std::string text(const T& v) {
  std::ostringstream s;
  s << std::boolalpha << v;
  return s.str();
}

std::string text(const std::vector<double>& v) {
  std::ostringstream s;
  s << "[";
  for (std::size_t i = 0; i < v.size(); ++i) s << (i ? ", " : "") << v[i];
  s << "]";
  return s.str();
}

// Reads one parameter into `field` and checks the whole config: the config validates before each call, so
// a new problem is this parameter's, and it stops the start-up with the parameter, its value and range.
class CheckedLoader {
 public:
  CheckedLoader(const ros::NodeHandle& pnh, LocalizerConfig& config, std::string log_name)
      : pnh_(pnh), config_(config), log_name_(std::move(log_name)) {}

  template <class T>
  void operator()(const std::string& name, T& field) {
    T value;
    if (!pnh_.getParam(name, value)) return;
    field = value;
    std::string problem = config_.validate();
    if (problem.empty()) return;
    while (!problem.empty() && (problem.back() == ' ' || problem.back() == ';')) problem.pop_back();
    throw std::invalid_argument("parameter ~" + name + " = " + text(value) + " is out of range (" + problem +
                                "); fix it in the launch file or YAML of " + log_name_);
  }

 private:
  const ros::NodeHandle& pnh_;
  LocalizerConfig& config_;
  std::string log_name_;
};

// Reads the word parameter `name` into `field` through `parse` (nullopt for a word it does not know); an unknown
// word stops the start-up with the parameter, its value and the `allowed` words.
template <class T>
void loadChoice(const ros::NodeHandle& pnh, const std::string& name, std::optional<T> (*parse)(const std::string&),
                const char* allowed, T& field) {
  std::string value;
  if (!pnh.getParam(name, value)) return;
  const std::optional<T> parsed = parse(value);
  if (!parsed) throw std::invalid_argument("~" + name + " '" + value + "' is unknown; use " + allowed);
  field = *parsed;
}

std::optional<NdtSearchMethod> searchMethod(const std::string& text) {
  NdtSearchMethod method;
  if (!parseSearchMethod(text, &method)) return std::nullopt;
  return method;
}

// fusion/mode first: the window's parameters are checked only when it may run.
void loadFusion(const ros::NodeHandle& pnh, CheckedLoader& load, FusionConfig& f, LocalizerRosParams& p) {
  loadChoice(pnh, "fusion/mode", parseFusionMode, "none, sliding_window or auto", f.mode);
  load("fusion/ndt_covariance_scale", f.ndt_covariance_scale);
  SlidingWindowConfig& w = f.window;
  load("fusion/window/gravity", w.gravity);
  load("fusion/window/gyro_noise_density", w.gyro_noise_density);
  load("fusion/window/accel_noise_density", w.accel_noise_density);
  load("fusion/window/gyro_random_walk", w.gyro_random_walk);
  load("fusion/window/accel_random_walk", w.accel_random_walk);
  load("fusion/window/max_states", w.max_states);
  load("fusion/window/reset_states", w.reset_states);
  load("fusion/window/max_imu_gap", w.max_imu_gap);
  load("fusion/window/zupt_max_speed", w.zupt_max_speed);
  load("fusion/window/odom_translation_std", w.odom_translation_std);
  load("fusion/window/odom_rotation_std", w.odom_rotation_std);
  load("fusion/window/max_iterations", w.max_iterations);
  std::vector<double> pose;
  if (pnh.getParam("fusion/window/base_T_imu", pose) && !pose.empty()) {
    bool finite = pose.size() == 6;
    for (double v : pose) finite = finite && std::isfinite(v);
    if (!finite)
      throw std::invalid_argument(
          "~fusion/window/base_T_imu must be 6 finite numbers [x y z roll pitch yaw] (m, rad), or [] to take the "
          "IMU's pose in the base frame from TF");
    w.base_T_imu = poseFromXyzRpy(XyzRpy(pose.data()));
    p.imu_extrinsic_from_tf = false;
  }
}

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
  load("preprocess/deskew_twist_smoothing", c.preprocess.deskew_twist_smoothing);
  load("prediction/max_extrapolation", c.prediction.max_extrapolation);
  load("prediction/max_speed", c.prediction.max_speed);
  load("prediction/max_yaw_rate", c.prediction.max_yaw_rate);
  load("prediction/margin", c.prediction.margin);
  load("prediction/max_radius", c.prediction.max_radius);  // max before min, as for the ranges
  load("prediction/min_radius", c.prediction.min_radius);
  load("prediction/min_yaw_range", c.prediction.min_yaw_range);
  load("hypotheses/yaw_step", c.hypotheses.yaw_step);
  load("hypotheses/yaw_count", c.hypotheses.yaw_count);
  load("hypotheses/refine", c.hypotheses.refine);
  load("hypotheses/screen_points", c.hypotheses.screen_points);
  load("hypotheses/poor_nvtl_ratio", c.hypotheses.poor_nvtl_ratio);
  load("lost/max_coast_time", c.lost.max_coast_time);
  load("lost/search_period", c.lost.search_period);
  load("lost/initial_pose_search_size", c.lost.initial_pose_search_size);
  load("lost/background_search", c.lost.background_search);
  pnh.param("preprocess/time_field", p.time_field, p.time_field);
  load("ndt/resolution", c.ndt.resolution);
  load("ndt/min_points_per_voxel", c.ndt.min_points_per_voxel);
  load("ndt/eigenvalue_ratio", c.ndt.eigenvalue_ratio);
  load("ndt/threads", c.ndt.threads);
  load("ndt/step_size", c.ndt.step_size);
  load("ndt/max_step_size", c.ndt.max_step_size);
  load("ndt/coarse_points", c.ndt.coarse_points);
  load("ndt/coarse_yaw_probe", c.ndt.coarse_yaw_probe);
  load("ndt/coarse_map_factor", c.ndt.coarse_map_factor);
  load("ndt/transformation_epsilon", c.ndt.transformation_epsilon);
  load("ndt/max_iterations", c.ndt.max_iterations);
  load("ndt/outlier_ratio", c.ndt.outlier_ratio);
  load("ndt/line_search", c.ndt.line_search);
  loadChoice(pnh, "ndt/search_method", searchMethod, "DIRECT1, DIRECT7, DIRECT27 or RADIUS", c.ndt.search);
  // The branch-and-bound search (GlobalLocalizationConfig; its NDT is ndt/* above but for its own epsilon).
  GlobalLocalizationConfig& gc = c.global;
  load("global_localization/resolution", gc.resolution);
  load("global_localization/ground_cell", gc.ground_cell);
  load("global_localization/height_bands", gc.height_bands);
  load("global_localization/band_overlap", gc.band_overlap);
  load("global_localization/max_range", gc.max_range);
  load("global_localization/max_scan_points", gc.max_scan_points);
  load("global_localization/min_scan_points", gc.min_scan_points);
  load("global_localization/blur_sigma", gc.blur_sigma);
  load("global_localization/yaw_step", gc.yaw_step);
  load("global_localization/levels", gc.levels);
  load("global_localization/max_poses", gc.max_poses);
  load("global_localization/adapted_initial_score", gc.adapted_initial_score);
  load("global_localization/initial_descents", gc.initial_descents);
  load("global_localization/min_score", gc.min_score);
  load("global_localization/max_runner_up_ratio", gc.max_runner_up_ratio);
  load("global_localization/runner_up_distance", gc.runner_up_distance);
  load("global_localization/runner_up_yaw", gc.runner_up_yaw);
  load("global_localization/refine_candidates", gc.refine_candidates);
  load("global_localization/same_pose_distance", gc.same_pose_distance);
  load("global_localization/same_pose_yaw", gc.same_pose_yaw);
  load("global_localization/transformation_epsilon", gc.ndt.transformation_epsilon);
  load("global_localization/min_inlier_fraction", gc.min_inlier_fraction);
  load("global_localization/max_refinement_shift", gc.max_refinement_shift);
  load("global_localization/threads", gc.threads);
  load("map_update_threads", c.map_update_threads);
  load("match/min_nvtl", c.match.min_nvtl);
  load("match/min_transformation_probability", c.match.min_transformation_probability);
  load("match/require_converged", c.match.require_converged);
  load("covariance/scale", c.covariance.scale);
  load("covariance/min_translation_std", c.covariance.min_translation_std);
  load("covariance/min_rotation_std", c.covariance.min_rotation_std);
  load("covariance/max_translation_std", c.covariance.max_translation_std);
  load("covariance/max_rotation_std", c.covariance.max_rotation_std);
  load("imu/use_gyro", c.imu.use_gyro);
  load("imu/max_gap", c.imu.max_gap);
  load("time_jump_back", c.time_jump_back);
  load("map_wait_half_side", c.map_wait_half_side);
  loadFusion(pnh, load, c.fusion, p);

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
    p.initial_pose = poseFromXyzRpy(XyzRpy(pose.data()));
  }
  pnh.getParam("save_pose_rate", p.save_pose_rate);
  if (!(p.save_pose_rate >= 0.0 && std::isfinite(p.save_pose_rate)))
    throw std::invalid_argument("~save_pose_rate must be >= 0 Hz, 0 = off (got " + text(p.save_pose_rate) + ")");
  if (const std::optional<XyzRpy> saved = readSavedPose(pnh, log_name)) p.last_pose = poseFromXyzRpy(*saved);

  GlobalLocalizationParams& g = p.global_localization;
  pnh.getParam("global_localization/auto_start_timeout", g.auto_start_timeout);
  if (!(g.auto_start_timeout >= 0.0))
    throw std::invalid_argument("~global_localization/auto_start_timeout must be >= 0 s, 0 = off (got " +
                                text(g.auto_start_timeout) + ")");
  pnh.getParam("global_localization/size", g.size);
  if (!(g.size > 0.0))
    throw std::invalid_argument("~global_localization/size must be > 0 m (got " + text(g.size) + ")");
  pnh.getParam("global_localization/yaw_range", g.yaw_range);
  if (!(g.yaw_range > 0.0 && g.yaw_range <= M_PI))
    throw std::invalid_argument("~global_localization/yaw_range must be in (0, pi] rad (got " + text(g.yaw_range) +
                                ")");
  std::vector<double> centre;
  if (pnh.getParam("global_localization/center", centre) && !centre.empty()) {
    if (centre.size() != 2 || !std::isfinite(centre[0]) || !std::isfinite(centre[1]))
      throw std::invalid_argument("~global_localization/center must be [x, y] (m, map frame) or []");
    g.center = Eigen::Vector2d(centre[0], centre[1]);
  }
  return p;
}

}  // namespace grid_puzzle_localization
