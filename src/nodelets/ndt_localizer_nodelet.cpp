// NDT localizer nodelet: PointCloud2 -> core Localizer -> Odometry, TF and status. All state and maths
// live in the core (localizer.hpp); this file wires topics, services and frames to it. Its parts are files of
// their own here: parameters, message conversions, the scan slot, tile delta input, TF output, the throttle of
// fusion warnings and the timer of the automatic global search. The last published pose is saved on the parameter
// server (~last_pose) so that a respawned process searches around it.
#include <geometry_msgs/PoseWithCovarianceStamped.h>
#include <nav_msgs/Odometry.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <sensor_msgs/Imu.h>
#include <sensor_msgs/PointCloud2.h>
#include <std_srvs/Trigger.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <pluginlib/class_list_macros.hpp>

#include "global_search_timer.hpp"
#include "grid_puzzle_localization/GlobalLocalize.h"
#include "grid_puzzle_localization/TileDelta.h"
#include "grid_puzzle_localization/localizer.hpp"
#include "grid_puzzle_localization/provider/window.hpp"
#include "grid_puzzle_localization/rpy.hpp"
#include "hint_msg.hpp"
#include "imu_msg.hpp"
#include "latest_scan_slot.hpp"
#include "localizer_params.hpp"
#include "map_store_params.hpp"
#include "map_tf_broadcaster.hpp"
#include "ndt_status_msg.hpp"
#include "odometry_msg.hpp"
#include "point_cloud_msg.hpp"
#include "saved_pose.hpp"
#include "tile_delta_input.hpp"
#include "warning_throttle.hpp"
#include "window_request.hpp"

namespace grid_puzzle_localization {

class NdtLocalizerNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    // Scan, pose and IMU callbacks share the single-threaded queue (they touch the localizer state in
    // order); map input uses the multi-threaded queue so converting a large map never delays a scan.
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& mt_nh = getMTNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    try {
      params_ = loadLocalizerParams(pnh, getName());
      localizer_ = std::make_unique<Localizer>(params_.core);
      localizer_->map().setMapStoreConfig(loadMapStoreConfig(pnh));  // a tile_dir given by URL (docs/map_store.md)
    } catch (const std::invalid_argument& e) {
      NODELET_FATAL("%s: %s", getName().c_str(), e.what());
      throw;
    }
    if (params_.initial_pose) localizer_->setDefaultInitialPose(*params_.initial_pose);
    // Consumed: a respawned process must not start again from the launch's pose (the vehicle has moved on);
    // it waits for initialpose or searches around the pose it saved in ~last_pose (global_localization/*).
    if (params_.initial_pose) pnh.deleteParam("initial_pose");
    if (params_.last_pose && !params_.initial_pose) {
      hint_ = Hint{params_.last_pose->translation().head<2>(), 0.0};  // an initialpose_hint message replaces it
      localizer_->map().setFocus(hint_->xy);
      if (params_.global_localization.auto_start_timeout > 0.0)
        NODELET_INFO(
            "no pose yet: resumes searching around (%.2f, %.2f), the last pose saved in ~last_pose, %.1f s "
            "after the first scan unless initialpose comes",
            hint_->xy.x(), hint_->xy.y(), params_.global_localization.auto_start_timeout);
      else
        NODELET_INFO(
            "the last pose saved in ~last_pose, (%.2f, %.2f), is the hint of a global search; none starts "
            "by itself (global_localization/auto_start_timeout is 0)",
            hint_->xy.x(), hint_->xy.y());
    }
    localizer_->map().setTileCacheMb(params_.tile_cache_mb);

    tf_buffer_ = std::make_unique<tf2_ros::Buffer>();
    tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh);
    map_tf_ = std::make_unique<MapTfBroadcaster>(*tf_buffer_, params_.map_frame, params_.odom_frame, params_.base_frame,
                                                 getName());
    global_search_timer_ = GlobalSearchTimer(params_.global_localization.auto_start_timeout);
    odom_pub_ = nh.advertise<nav_msgs::Odometry>("odom", 10);
    status_pub_ = pnh.advertise<NdtStatus>("status", 10);
    if (params_.publish_aligned_points) aligned_pub_ = nh.advertise<sensor_msgs::PointCloud2>("aligned_points", 2);

    if (params_.map_source == "cloud") {
      map_sub_ = mt_nh.subscribe("map_cloud", 1, &NdtLocalizerNodelet::onMapCloud, this);
    } else if (params_.map_source == "tiles") {
      map_sub_ = mt_nh.subscribe("tile_delta", 100, &NdtLocalizerNodelet::onTileDelta, this);
      tile_input_ = std::make_unique<TileDeltaInput>(mt_nh.serviceClient<std_srvs::Trigger>(params_.resend_service),
                                                     params_.core.ndt.resolution, getName());
      window_request_ = std::make_unique<WindowRequest>(mt_nh, params_.resend_service, getName());
    } else {
      localizer_->map().submit(MapChange::pcdFile(params_.pcd_path));
    }
    // Scans arrive on the multi-threaded queue and wait in a slot of one; a newer scan replaces one not yet
    // taken (counted in status.scans_dropped), so a slow localizer skips scans instead of falling behind.
    // roscpp's queue before the slot drops uncounted only when even that trivial callback stalls for 5 scans.
    points_sub_ = mt_nh.subscribe("points", 5, &NdtLocalizerNodelet::onPointsArrived, this);
    initial_pose_sub_ = nh.subscribe("initialpose", 1, &NdtLocalizerNodelet::onInitialPose, this);
    imu_sub_ = nh.subscribe("imu", 200, &NdtLocalizerNodelet::onImu, this);
    if (localizer_->fusion().mayRun())
      odom_in_sub_ = nh.subscribe("odom_in", 50, &NdtLocalizerNodelet::onOdometryIn, this);
    hint_sub_ = nh.subscribe("initialpose_hint", 1, &NdtLocalizerNodelet::onHint, this);
    global_srv_ = pnh.advertiseService("global_localize", &NdtLocalizerNodelet::onGlobalLocalize, this);
    // The parameter server is an XML-RPC call away: the pose is written from the multi-threaded queue.
    saved_pose_ = std::make_unique<SavedPoseWriter>(mt_nh, pnh, params_.save_pose_rate);
    NODELET_INFO("%s: map source '%s', frames %s -> %s, resolution %.2f m, search %s, fusion %s", getName().c_str(),
                 params_.map_source.c_str(), params_.map_frame.c_str(), params_.base_frame.c_str(),
                 params_.core.ndt.resolution, toString(params_.core.ndt.search), toString(params_.core.fusion.mode));
  }

  // --------------------------------------------------------------- map input (multi-threaded queue)
  void onMapCloud(const sensor_msgs::PointCloud2::ConstPtr& msg) {
    if (!checkMapFrame(msg->header.frame_id, "map_cloud")) return;
    try {
      localizer_->map().submit(MapChange::fullCloud(fromMsg(*msg)));
      ++map_replacements_;
    } catch (const std::invalid_argument& e) {
      NODELET_ERROR("map_cloud: %s", e.what());
    }
  }

  void onTileDelta(const TileDelta::ConstPtr& msg) {
    if (!checkMapFrame(msg->header.frame_id, "tile_delta")) return;
    std::optional<MapChange> change = tile_input_->accept(*msg, localizer_->map());
    if (!change) return;
    localizer_->map().submit(std::move(*change));
    if (msg->reset) {
      ++map_replacements_;
      window_request_->received();
    }
  }

  bool checkMapFrame(const std::string& frame, const char* topic) {
    if (frame.empty() || frame == params_.map_frame) return true;
    NODELET_ERROR_THROTTLE(5.0, "%s is in frame '%s' but ~map_frame is '%s'; ignored: publish it in the map frame",
                           topic, frame.c_str(), params_.map_frame.c_str());
    return false;
  }

  // --------------------------------------------------------------- scan thread (single-threaded queue)
  void onInitialPose(const geometry_msgs::PoseWithCovarianceStamped::ConstPtr& msg) {
    if (!checkMapFrame(msg->header.frame_id, "initialpose")) return;
    Eigen::Isometry3d pose;
    tf2::fromMsg(msg->pose.pose, pose);
    if (!pose.matrix().allFinite()) {
      NODELET_ERROR("initialpose has a non-finite pose; ignored");
      return;
    }
    localizer_->setInitialPose(pose);
    NODELET_INFO("initial pose set to (%.2f, %.2f, %.2f)", pose.translation().x(), pose.translation().y(),
                 pose.translation().z());
  }

  void onImu(const sensor_msgs::Imu::ConstPtr& msg) {
    if (params_.imu_extrinsic_from_tf) {
      const std::optional<Eigen::Isometry3d> base_T_imu = staticTransform(msg->header.frame_id);
      if (!base_T_imu) return;
      if (!base_T_imu->isApprox(localizer_->fusion().baseTImu())) localizer_->fusion().setBaseTImu(*base_T_imu);
    }
    localizer_->addImu(imuSampleFromMsg(*msg));
    logFusionWarnings();
  }

  // Wheel odometry (odom_T_base) for the window's relative pose factors.
  void onOdometryIn(const nav_msgs::Odometry::ConstPtr& msg) {
    if (!msg->child_frame_id.empty() && msg->child_frame_id != params_.base_frame) {
      NODELET_ERROR_THROTTLE(5.0, "odom_in is the pose of '%s' but ~base_frame is '%s'; odometry ignored",
                             msg->child_frame_id.c_str(), params_.base_frame.c_str());
      return;
    }
    Eigen::Isometry3d odom_T_base;
    tf2::fromMsg(msg->pose.pose, odom_T_base);
    if (!odom_T_base.matrix().allFinite()) {
      NODELET_WARN_THROTTLE(5.0, "odom_in has a non-finite pose; ignored");
      return;
    }
    localizer_->fusion().addOdometry(msg->header.stamp.toSec(), odom_T_base);
  }

  // Each kind of fusion warning (its text without the numbers) at most once per 5 s.
  void logFusionWarnings() {
    const double now = ros::WallTime::now().toSec();
    for (const std::string& warning : localizer_->fusion().takeWarnings())
      if (fusion_warnings_.pass(warning, now)) NODELET_WARN("fusion: %s", warning.c_str());
  }

  void onPointsArrived(const sensor_msgs::PointCloud2::ConstPtr& msg) {
    scan_slot_.put(msg);
    getNodeHandle().getCallbackQueue()->addCallback(boost::make_shared<TakeScan>(this));
  }

  struct TakeScan : ros::CallbackInterface {
    explicit TakeScan(NdtLocalizerNodelet* n) : nodelet(n) {}
    CallResult call() override {
      const sensor_msgs::PointCloud2::ConstPtr msg = nodelet->scan_slot_.take();
      if (msg) nodelet->onPoints(msg);  // else a newer scan's callback already took it
      return Success;
    }
    NdtLocalizerNodelet* nodelet;
  };

  void onPoints(const sensor_msgs::PointCloud2::ConstPtr& msg) {
    for (const std::string& err : localizer_->map().takeErrors()) NODELET_ERROR("map update failed: %s", err.c_str());
    const std::optional<Eigen::Isometry3d> base_T_sensor = staticTransform(msg->header.frame_id);
    if (!base_T_sensor) return;
    PointCloud scan;
    std::optional<PointTimes> times;
    try {
      scan = fromMsg(*msg);
      if (params_.core.preprocess.deskew) times = timesFromMsg(*msg, params_.time_field);
    } catch (const std::invalid_argument& e) {
      NODELET_ERROR_THROTTLE(5.0, "points (frame '%s'): %s", msg->header.frame_id.c_str(), e.what());
      return;
    }
    if (params_.core.preprocess.deskew && !times)
      NODELET_WARN_ONCE(
          "points have no per-point time field '%s': scans are not deskewed (set "
          "~preprocess/time_field, or ~preprocess/deskew false to silence this)",
          params_.time_field.c_str());
    LocalizerOutput out =
        localizer_->processScan(msg->header.stamp.toSec(), scan, *base_T_sensor, times ? &*times : nullptr);
    // A whole map after the first (a map_cloud, a reset tile_delta) is a block switch (block_map mode) or a reset
    // of the map source (a respawned provider, a resend): the window keeps N_r states.
    const int replacements = map_replacements_;
    if (out.map_swapped && replacements != map_replacements_seen_) {
      if (map_replacements_seen_ > 0) localizer_->fusion().mapSwitched();
      map_replacements_seen_ = replacements;
    }
    logFusionWarnings();
    if (out.reset) NODELET_WARN("scan time went backwards (bag loop?): localizer reset");
    // A start search beside the scan thread finished before this scan (found: this scan was matched from it).
    if (out.start_search) reportStartSearch(*out.start_search, msg->header.stamp.toSec());
    reportState(out.state);
    if (out.state == LocalizerState::kWaitingForInitialPose && maybeStartGlobalLocalization(msg->header.stamp)) {
      // The start was found for this scan (a search within the call): the scan is matched from it, and published
      // like the next ones.
      out = localizer_->processScan(msg->header.stamp.toSec(), scan, *base_T_sensor, times ? &*times : nullptr);
      reportState(out.state);
    }
    if (out.tiles_awaited > 0)
      NODELET_INFO_THROTTLE(2.0,
                            "waiting for the map: %zu tiles of the window still loading, %zu of them near the pose",
                            out.tiles_in_flight, out.tiles_awaited);
    if (out.state != LocalizerState::kTracking) {
      publish(out, msg->header);  // the status says why it waits; nothing else goes out
      return;
    }
    if (out.recovered)
      NODELET_WARN("recovered: matching again after %.1f s without an accepted match%s", out.since_last_match,
                   out.global_search ? " (global search)" : "");
    else if (out.global_search && out.lost)
      NODELET_WARN_THROTTLE(2.0, "lost: global search around the last pose found nothing: %s",
                            out.global_search_reason.c_str());
    else if (out.global_search && !out.global_search_reason.empty())
      NODELET_INFO_THROTTLE(2.0,
                            "global search around the last pose refused (%s); the match from the prediction stands",
                            out.global_search_reason.c_str());
    if (out.lost)
      NODELET_WARN_THROTTLE(2.0, "lost: no acceptable match for %.1f s (NVTL %.2f); %s", out.since_last_match,
                            out.ndt.nvtl,
                            out.publish ? "publishing the bounded prediction"
                                        : "not publishing odometry or TF (lost/max_coast_time exceeded)");
    publish(out, msg->header);
  }

  // Starts a global search when an initialpose_hint came while no pose is known (again every lost/search_period
  // until one is found), or when no initial pose came within global_localization/auto_start_timeout. An answer is
  // taken once the search of a later scan agrees with it (Localizer::searchForStart): while one is held, the next
  // scan is searched at once. With lost/background_search the search runs beside the scan thread and a later scan
  // judges it (LocalizerOutput::start_search). True when the start was taken within this call.
  bool maybeStartGlobalLocalization(const ros::Time& stamp) {
    if (localizer_->searching()) return false;  // one start search at a time
    const double t = stamp.toSec();
    const bool confirming = localizer_->startAwaitsConfirmation();
    const bool hinted =
        hint_due_ && (confirming || !last_hint_search_ || t - *last_hint_search_ >= params_.core.lost.search_period ||
                      t < *last_hint_search_);
    if (!hinted && !confirming && !global_search_timer_.due(t)) return false;
    GlobalLocalize::Request req;
    const std::optional<Eigen::Vector2d> centre = hint_ ? hint_->xy : params_.global_localization.center;
    if (centre) {
      req.use_center = true;
      req.center_x = centre->x();
      req.center_y = centre->y();
      // A hint's square reaches as far as its covariance says, at least global_localization/size.
      if (hint_) req.size = std::max(params_.global_localization.size, hint_->size);
    }
    if (hinted) last_hint_search_ = t;
    const std::optional<SearchRegion> region = requestedRegion(req);
    if (!region) return false;  // no map yet
    const std::optional<StartSearch> start = localizer_->startSearchForStart(*region);
    if (!start) return false;  // runs beside the scan thread
    if (start->tiles_awaited > 0) {
      NODELET_INFO_THROTTLE(2.0, "global localization %s", start->search.reason.c_str());
      return false;
    }
    reportStartSearch(*start, t);
    return start->search.found;
  }

  // Logs a start search's judged answer for the scan at `t` [s]; a search that found nothing is tried again after
  // another timeout (at once while an answer is held).
  void reportStartSearch(const StartSearch& start, double t) {
    const GlobalLocalizationResult& r = start.search;
    if (r.found) {
      logFound(r);
      hint_due_ = false;
    } else if (start.held) {
      NODELET_INFO("global localization: (%.2f, %.2f) %s", r.map_T_base.translation().x(),
                   r.map_T_base.translation().y(), r.reason.c_str());
    } else {
      NODELET_WARN("global localization failed: %s", r.reason.c_str());
      global_search_timer_.failed(t);
    }
  }

  void onHint(const geometry_msgs::PoseWithCovarianceStamped::ConstPtr& msg) {
    const HintRegion hint = hintRegionOf(*msg, params_.map_frame);
    if (!hint.region) {
      NODELET_ERROR("%s", hint.error.c_str());
      return;
    }
    const LostSearchRegion& region = *hint.region;
    const double x = region.x, y = region.y;
    // With tiles the loaded map is only the provider's window: the provider checks a hint against the whole map.
    const std::optional<Eigen::AlignedBox3d> box =
        params_.map_source == "tiles" ? std::nullopt : localizer_->mapBounds();
    if (box && (x + region.radius < box->min().x() || x - region.radius > box->max().x() ||
                y + region.radius < box->min().y() || y - region.radius > box->max().y())) {
      NODELET_ERROR(
          "initialpose_hint (%.1f, %.1f) m (search radius %.1f m) lies outside the map, which spans x "
          "%.0f..%.0f m, y %.0f..%.0f m; ignored: check the hint's frame and origin",
          x, y, region.radius, box->min().x(), box->max().x(), box->min().y(), box->max().y());
      return;
    }
    hint_ = Hint{Eigen::Vector2d(x, y), 2.0 * region.radius};
    localizer_->map().setFocus(hint_->xy);
    if (!localizer_->lastAcceptedPose()) {
      hint_due_ = true;  // searched at the next scan that waits for a pose
      last_hint_search_.reset();
    }
    NODELET_INFO("initialpose_hint (%.1f, %.1f) m, search radius %.1f m%s", x, y, region.radius,
                 hint_due_ ? ": global search at the next scan" : "");
  }

  // The search region of a request: see srv/GlobalLocalize.srv. None without a map.
  std::optional<SearchRegion> requestedRegion(const GlobalLocalize::Request& req) const {
    const GlobalLocalizationParams& g = params_.global_localization;
    SearchRegion region;
    const double size = req.size > 0.0 ? req.size : g.size;
    region.radius = 0.5 * size;  // the square searched is 2 * radius on a side
    region.yaw_range = req.yaw_range > 0.0 ? std::min<double>(req.yaw_range, M_PI) : g.yaw_range;
    if (req.use_center) {
      region.centre = poseFromXyzRpy((XyzRpy() << req.center_x, req.center_y, 0.0, 0.0, 0.0, req.yaw).finished());
    } else if (const std::optional<Eigen::Isometry3d> last = localizer_->lastAcceptedPose()) {
      region.centre = *last;
    } else if (const std::optional<Eigen::AlignedBox3d> box = localizer_->mapBounds()) {
      region.centre.translation() = box->center();
      region.radius = 0.5 * box->sizes().head<2>().maxCoeff();
    } else {
      return std::nullopt;
    }
    return region;
  }

  void logFound(const GlobalLocalizationResult& r) {
    NODELET_INFO("global localization: (%.2f, %.2f), score %.2f, runner-up %.2f, %.2f s",
                 r.map_T_base.translation().x(), r.map_T_base.translation().y(), r.score, r.runner_up_score, r.seconds);
  }

  bool onGlobalLocalize(GlobalLocalize::Request& req, GlobalLocalize::Response& res) {
    const std::optional<SearchRegion> region = requestedRegion(req);
    if (!region) {
      res.message = "no map loaded yet";
      return true;
    }
    const GlobalLocalizationResult r = localizer_->globalLocalize(*region);
    res.candidates = static_cast<std::uint32_t>(r.candidates_evaluated);
    res.score = r.score;
    res.runner_up_score = r.runner_up_score;
    res.success = r.found;
    if (r.found) {
      res.pose = tf2::toMsg(r.map_T_base);
      logFound(r);
    } else {
      res.message = r.reason;
      NODELET_WARN("global localization failed: %s", r.reason.c_str());
    }
    return true;
  }

  void reportState(LocalizerState state) {
    if (state == last_state_) return;
    last_state_ = state;
    if (state == LocalizerState::kWaitingForMap)
      NODELET_INFO("waiting for the map (map_source '%s')", params_.map_source.c_str());
    else if (state == LocalizerState::kWaitingForInitialPose)
      NODELET_INFO("waiting for an initial pose on %s (or set ~initial_pose)", initial_pose_sub_.getTopic().c_str());
    else
      NODELET_INFO("tracking");
  }

  /// base_T_frame from static TF, cached per frame; logs the frames on failure.
  std::optional<Eigen::Isometry3d> staticTransform(const std::string& frame) {
    const auto it = static_cache_.find(frame);
    if (it != static_cache_.end()) return it->second;
    try {
      const geometry_msgs::TransformStamped t = tf_buffer_->lookupTransform(params_.base_frame, frame, ros::Time(0));
      const Eigen::Isometry3d iso = tf2::transformToEigen(t);
      static_cache_.emplace(frame, iso);
      return iso;
    } catch (const tf2::TransformException& e) {
      NODELET_ERROR_THROTTLE(5.0, "no transform from '%s' to '%s' (%s); publish it as a static transform",
                             frame.c_str(), params_.base_frame.c_str(), e.what());
      return std::nullopt;
    }
  }

  // --------------------------------------------------------------- output
  void publish(const LocalizerOutput& out, const std_msgs::Header& scan_header) {
    std_msgs::Header status_header = scan_header;
    status_header.frame_id = params_.map_frame;
    NdtStatus status = toStatusMsg(out, status_header, localizer_->map().stats(), params_.map_source);
    status.scans_dropped = scan_slot_.dropped();
    status.window_states = static_cast<std::uint32_t>(localizer_->fusion().states());
    if (status.scans_dropped > warned_drops_) {
      NODELET_WARN_THROTTLE(5.0, "%lu scans dropped so far: scans arrive faster than they are matched",
                            static_cast<unsigned long>(status.scans_dropped));
      warned_drops_ = status.scans_dropped;
    }
    status_pub_.publish(status);
    if (!out.publish) return;  // lost for longer than lost/max_coast_time: no pose rather than a wrong one
    odom_pub_.publish(toOdometryMsg(out, scan_header.stamp, params_.map_frame, params_.base_frame));
    if (params_.publish_tf) map_tf_->send(out.pose, scan_header.stamp);
    if (params_.save_pose_rate > 0.0) saved_pose_->set(xyzRpyFromPose(out.pose), scan_header.stamp.toSec());

    if (params_.publish_aligned_points && aligned_pub_.getNumSubscribers() > 0) {
      std_msgs::Header h = scan_header;
      h.frame_id = params_.map_frame;
      aligned_pub_.publish(toMsg(out.aligned, h));
    }
  }

  LocalizerRosParams params_;
  std::unique_ptr<Localizer> localizer_;
  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  std::unique_ptr<MapTfBroadcaster> map_tf_;               // scan thread only
  std::map<std::string, Eigen::Isometry3d> static_cache_;  // scan thread only
  std::unique_ptr<TileDeltaInput> tile_input_;             // tiles mode; tile_delta callback only (never concurrent)
  std::unique_ptr<WindowRequest> window_request_;          // tiles mode: asks for the window until one comes
  std::optional<LocalizerState> last_state_;               // for logging each state change once
  std::atomic<int> map_replacements_{0};                   // whole maps taken (multi-threaded queue)
  int map_replacements_seen_ = 0;                          // scan thread: map_replacements_ at the last map swap
  WarningThrottle fusion_warnings_{5.0};                   // scan thread
  GlobalSearchTimer global_search_timer_{0.0};             // scan thread; set from the parameters in onInit
  struct Hint {
    Eigen::Vector2d xy;  // [m] map frame
    double size = 0.0;   // [m] side of the square its covariance covers (0: none given)
  };
  std::optional<Hint> hint_;                // last initialpose_hint, else the saved ~last_pose; scan thread
  bool hint_due_ = false;                   // a hint came while no pose is known: search around it
  std::optional<double> last_hint_search_;  // [s] scan stamp of the last search around it
  LatestScanSlot<sensor_msgs::PointCloud2::ConstPtr> scan_slot_;  // points (MT queue) -> scan thread
  std::uint64_t warned_drops_ = 0;                                // scan thread only
  std::unique_ptr<SavedPoseWriter> saved_pose_;                   // ~last_pose

  ros::Publisher odom_pub_, status_pub_, aligned_pub_;
  ros::Subscriber points_sub_, initial_pose_sub_, imu_sub_, odom_in_sub_, map_sub_, hint_sub_;
  ros::ServiceServer global_srv_;
};

}  // namespace grid_puzzle_localization

PLUGINLIB_EXPORT_CLASS(grid_puzzle_localization::NdtLocalizerNodelet, nodelet::Nodelet)
