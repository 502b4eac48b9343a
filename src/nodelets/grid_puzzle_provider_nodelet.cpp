// Grid puzzle provider nodelet: the rospy grid_puzzle_map_provider's parameters, topics and TileDelta protocol in
// the localizer's nodelet manager, so the provider costs no process of its own and its deltas reach the localizer
// as shared pointers. The window maths and tile sets live in the core (provider/window_server.hpp, the twin of the
// rospy node's provider/window_server.py); this file wires them to ROS.
//
// Callbacks only store the newest pose, search region or end of a search; a worker thread feeds them to the window
// server and publishes each change of the window by reference on `tile_delta` (the localizer reads the files) and
// the latched `~status`. A new subscriber first receives a reset delta of the whole window at the current revision;
// `~resend` (std_srvs/Trigger) broadcasts one. A tile directory rewritten under the running nodelet (a new index
// revision) is reopened and the whole window sent again as a reset; one that cannot be opened is retried. A tile
// directory given by URL (http(s)://, a map store: docs/map_store.md) is read through its index.json, polled every
// map_store/poll_period with its ETag, outside the window's lock.
// The newest pose is kept on the parameter server (~last_pose, save_pose_rate): killed with its manager (and the
// localizer in it) and respawned, the nodelet serves the window there until a pose arrives, so the respawned
// localizer has the map its global search around its own saved pose needs.
#include <geometry_msgs/PoseWithCovarianceStamped.h>
#include <nav_msgs/Odometry.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <std_srvs/Trigger.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <mutex>
#include <optional>
#include <pluginlib/class_list_macros.hpp>
#include <thread>

#include "grid_puzzle_localization/NdtStatus.h"
#include "grid_puzzle_localization/ProviderStatus.h"
#include "grid_puzzle_localization/TileDelta.h"
#include "grid_puzzle_localization/map_store/map_store.hpp"
#include "grid_puzzle_localization/provider/window_server.hpp"
#include "hint_msg.hpp"
#include "map_store_params.hpp"
#include "provider_map_cloud.hpp"
#include "provider_msgs.hpp"
#include "provider_params.hpp"
#include "saved_pose.hpp"

namespace grid_puzzle_localization {

class GridPuzzleProviderNodelet : public nodelet::Nodelet {
 public:
  ~GridPuzzleProviderNodelet() override {
    {
      std::lock_guard<std::mutex> lock(input_mutex_);
      stop_ = true;
    }
    input_ready_.notify_all();
    if (worker_.joinable()) worker_.join();
  }

 private:
  static constexpr double kWarnPeriod = 5.0;  // [s] throttle of repeated warnings

  void onInit() override {
    ros::NodeHandle& nh = getMTNodeHandle();
    ros::NodeHandle& pnh = getMTPrivateNodeHandle();
    try {
      config_ = loadProviderConfig(pnh);
      store_config_ = loadMapStoreConfig(pnh);
      // tile_delta names the directory the localizer reads: absolute, whatever the manager's working directory.
      if (config_.tiles_dir.front() != '/' && !isMapStoreUrl(config_.tiles_dir))
        config_.tiles_dir = (std::filesystem::current_path() / config_.tiles_dir);
    } catch (const std::invalid_argument& e) {
      NODELET_FATAL("%s: %s", getName().c_str(), e.what());
      throw;
    }
    delta_pub_ = nh.advertise<TileDelta>(
        "tile_delta", 50, [this](const ros::SingleSubscriberPublisher& peer) { sendReset(peer); },
        ros::SubscriberStatusCallback());
    status_pub_ = pnh.advertise<ProviderStatus>("status", 10, true);
    // map_cloud merges the window's tile files, which a map given by URL does not have locally.
    if (config_.publish_map_cloud && isMapStoreUrl(config_.tiles_dir))
      NODELET_ERROR("%s: publish_map_cloud needs a local tile directory, not the URL %s; map_cloud is not published",
                    getName().c_str(), config_.tiles_dir.c_str());
    else if (config_.publish_map_cloud)
      map_cloud_ = std::make_unique<ProviderMapCloud>(nh, config_.map_frame, config_.map_cloud_period);
    resend_srv_ = pnh.advertiseService("resend", &GridPuzzleProviderNodelet::onResend, this);
    // A map given by URL is opened now: with its server unreachable and no index of it in the cache there is
    // nothing to serve, and the nodelet stops here naming the URL (a directory is waited for: a disk mounted late).
    if (isMapStoreUrl(config_.tiles_dir)) {
      try {
        openServer();
      } catch (const std::exception& e) {
        NODELET_FATAL("%s: %s", getName().c_str(), e.what());
        throw;
      }
    }
    if (config_.pose_source == "odom") {
      pose_sub_ = nh.subscribe("odom", 1, &GridPuzzleProviderNodelet::onOdom, this);
      // The localizer publishes odom only once it has a map, which comes from here: the start pose seeds the
      // first window.
      initial_pose_sub_ = nh.subscribe("initialpose", 1, &GridPuzzleProviderNodelet::onInitialPose, this);
    } else {
      pose_sub_ = nh.subscribe("pose", 1, &GridPuzzleProviderNodelet::onPose, this);
    }
    // The localizer's status: a start it carries while the start's map arrives, and the region it searches when lost.
    if (config_.pose_source == "odom" || config_.lost_max_half_side > 0.0)
      status_sub_ = nh.subscribe("localizer_status", 1, &GridPuzzleProviderNodelet::onLocalizerStatus, this);
    hint_sub_ = nh.subscribe("initialpose_hint", 1, &GridPuzzleProviderNodelet::onHint, this);
    saved_pose_ = std::make_unique<SavedPoseWriter>(nh, pnh, config_.save_pose_rate);
    if (const std::optional<XyzRpy> saved = readSavedPose(pnh, getName())) {
      NODELET_INFO("%s: serves the window around (%.2f, %.2f), the pose saved in ~last_pose, until a pose arrives",
                   getName().c_str(), (*saved)(0), (*saved)(1));
      PoseSample resume;
      resume.x = (*saved)(0);
      resume.y = (*saved)(1);
      resume.yaw = (*saved)(5);
      latest_ = resume;
      posed_ = true;
    }
    worker_ = std::thread(&GridPuzzleProviderNodelet::run, this);
  }

  // ------------------------------------------------------------ callbacks (never block on the window)
  void onOdom(const nav_msgs::Odometry::ConstPtr& msg) {
    if (frameOk(msg->header.frame_id)) offer(poseSampleOf(msg->pose.pose, msg->header.stamp, &msg->twist.twist));
  }

  void onPose(const geometry_msgs::PoseWithCovarianceStamped::ConstPtr& msg) {
    if (frameOk(msg->header.frame_id)) offer(poseSampleOf(msg->pose.pose, msg->header.stamp, nullptr));
  }

  // A pose given by hand (rviz) ends a search's window: the window goes to that pose.
  void onInitialPose(const geometry_msgs::PoseWithCovarianceStamped::ConstPtr& msg) {
    {
      std::lock_guard<std::mutex> lock(input_mutex_);
      search_.reset();
      tracking_again_ = true;
    }
    onPose(msg);
  }

  void onLocalizerStatus(const NdtStatus::ConstPtr& msg) {
    // A start the localizer carries while its map arrives (the vehicle drives on): the window goes with it.
    if (msg->start_pending && config_.pose_source == "odom") {
      PoseSample start;
      start.x = msg->start_x;
      start.y = msg->start_y;
      start.t = msg->header.stamp.toSec();
      start.yaw = msg->start_yaw;
      offer(start);
    }
    if (config_.lost_max_half_side <= 0.0) return;
    {
      std::lock_guard<std::mutex> lock(input_mutex_);
      // The window grows for a search only once its tiles have all arrived: a growth queued behind a window still
      // loading would only slow what the robot needs now.
      if (msg->lost && msg->search_radius > 0.0 && msg->tiles_in_flight == 0) {
        search_ = LostSearchRegion{msg->search_x, msg->search_y, msg->search_radius, msg->header.stamp.toSec()};
        tracking_again_ = false;
      } else if (msg->match_accepted) {
        search_.reset();
        tracking_again_ = true;
      } else {
        return;
      }
    }
    input_ready_.notify_one();
  }

  bool frameOk(const std::string& frame) {
    if (frame.empty() || frame == config_.map_frame) return true;
    NODELET_WARN_THROTTLE(kWarnPeriod, "ignoring a pose in frame '%s': poses must be in map_frame '%s'", frame.c_str(),
                          config_.map_frame.c_str());
    return false;
  }

  // A coarse position (GNSS) before any pose: the window holds the localizer's search around it.
  void onHint(const geometry_msgs::PoseWithCovarianceStamped::ConstPtr& msg) {
    const HintRegion hint = hintRegionOf(*msg, config_.map_frame);
    if (!hint.region) {
      NODELET_ERROR("%s", hint.error.c_str());
      return;
    }
    const LostSearchRegion& region = *hint.region;
    {
      std::lock_guard<std::mutex> lock(server_mutex_);
      if (server_ && !server_->touchesMap(region)) {
        const MapExtent m = server_->mapExtent();
        NODELET_ERROR(
            "initialpose_hint (%.1f, %.1f) m (search radius %.1f m) lies outside the map, which spans x "
            "%.0f..%.0f m, y %.0f..%.0f m; ignored: check the hint's frame and origin",
            region.x, region.y, region.radius, m.x_min, m.x_max, m.y_min, m.y_max);
        return;
      }
    }
    {
      std::lock_guard<std::mutex> lock(input_mutex_);
      if (posed_) return;  // the localizer has a pose: its own search uses the hint
      search_ = region;
    }
    input_ready_.notify_one();
  }

  void offer(const PoseSample& pose) {
    {
      std::lock_guard<std::mutex> lock(input_mutex_);
      latest_ = pose;
      posed_ = true;
    }
    input_ready_.notify_one();
  }

  bool onResend(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
    const std::optional<std::uint32_t> sent = broadcastReset();
    res.success = sent.has_value();
    res.message = sent ? "revision " + std::to_string(*sent) + ": reset delta of the whole window"
                       : "no window yet: no pose has arrived";
    return true;
  }

  // ------------------------------------------------------------ worker
  void run() {
    while (true) {
      std::optional<PoseSample> pose;
      std::optional<LostSearchRegion> search;
      bool tracking_again = false;
      {
        std::unique_lock<std::mutex> lock(input_mutex_);
        if (!latest_ && !search_ && !tracking_again_ && !stop_)
          input_ready_.wait_for(lock, std::chrono::milliseconds(500));
        if (stop_ || !ros::ok()) return;
        std::swap(pose, latest_);
        std::swap(search, search_);
        std::swap(tracking_again, tracking_again_);
      }
      if (!openDirectory()) continue;
      pollStore();
      if (tracking_again) {
        std::lock_guard<std::mutex> lock(server_mutex_);
        server_->endSearch();  // the next pose is measured again: the window goes back to it
      }
      followDirectory();
      if (search) coverSearch(*search);
      maybeServeWholeMap();
      if (pose) {
        if (config_.save_pose_rate > 0.0)
          saved_pose_->set((XyzRpy() << pose->x, pose->y, 0.0, 0.0, 0.0, pose->yaw.value_or(0.0)).finished(), pose->t);
        const auto start = std::chrono::steady_clock::now();
        std::optional<Served> served;
        {
          std::lock_guard<std::mutex> lock(server_mutex_);
          served = server_->onPose(*pose);
        }
        if (served) publish(*served, start);
      }
    }
  }

  // Opens the tile directory on the first call, and again after each failure (a disk mounted late); false while it
  // cannot be opened.
  bool openDirectory() {
    if (server_) return true;
    try {
      openServer();
      return true;
    } catch (const std::exception& e) {
      NODELET_ERROR_THROTTLE(kWarnPeriod, "%s: %s; serving no tiles until it can be opened (retrying)",
                             getName().c_str(), e.what());
      std::this_thread::sleep_for(std::chrono::milliseconds(500));
      return false;
    }
  }

  // The window server on the tile directory or map store; throws naming the directory or URL and what failed.
  void openServer() {
    TileDirectory directory =
        isMapStoreUrl(config_.tiles_dir) ? openStore() : openTileDirectory(config_.tiles_dir, config_.tiles_grid_size);
    const std::size_t tiles = directory.tiles.size();
    if (!directory.unparsable.empty())
      NODELET_WARN("%s: %zu .pcd files are not tiles of side %g m and are ignored, e.g. %s", config_.tiles_dir.c_str(),
                   directory.unparsable.size(), directory.grid_size, directory.unparsable.front().c_str());
    const std::string source = directory.source;
    std::lock_guard<std::mutex> lock(server_mutex_);
    server_.emplace(config_.window, config_.lost_max_half_side, std::move(directory));
    s_ = server_->tiles().directory().grid_size;
    NODELET_INFO("%s: %zu tiles of %g m in %s (%s), n=%d k=%d, update distance %g m, listening on %s",
                 getName().c_str(), tiles, s_, config_.tiles_dir.c_str(), source.c_str(), server_->tracker().config().n,
                 server_->tracker().config().k, server_->tracker().updateDistance(), config_.pose_source.c_str());
  }

  // The tile directory given by URL, through its index (fetched over the network, or the cache's when the server is
  // down and the cache holds one).
  TileDirectory openStore() {
    if (!store_) store_ = std::make_unique<MapStore>(config_.tiles_dir, store_config_);
    remote_ = std::make_shared<RemoteTileIndex>();
    TileDirectory directory = tileDirectoryOfIndex(store_->url(), store_->index(), config_.tiles_grid_size);
    remote_->set(directory, store_->status().revision);
    directory.remote = remote_;
    next_poll_ = nextPoll();
    reportStore();
    return directory;
  }

  std::chrono::steady_clock::time_point nextPoll() const {
    return std::chrono::steady_clock::now() + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                                  std::chrono::duration<double>(store_config_.poll_period));
  }

  // Polls the map store's index.json when due (outside the window's lock: the network may be slow); a new revision
  // is handed to the window's tile references, whose refresh then sends the whole window as a reset.
  void pollStore() {
    if (!store_ || std::chrono::steady_clock::now() < next_poll_) return;
    next_poll_ = nextPoll();
    try {
      if (store_->pollIndex())
        remote_->set(tileDirectoryOfIndex(store_->url(), store_->index(), config_.tiles_grid_size),
                     store_->status().revision);
    } catch (const std::exception& e) {
      NODELET_ERROR_THROTTLE(kWarnPeriod, "map store %s: new index not used: %s", store_->url().c_str(), e.what());
    }
    reportStore();
  }

  // Says when the map store's server stops or starts answering (the window keeps being served meanwhile).
  void reportStore() {
    const MapStoreStatus status = store_->status();
    if (!status.reachable)
      NODELET_WARN_THROTTLE(kWarnPeriod,
                            "map store %s unreachable (%s): serving the tiles of index revision %s, retrying every "
                            "%g s",
                            status.url.c_str(), status.last_error.c_str(), status.revision.c_str(),
                            store_config_.poll_period);
    else if (!store_reachable_)
      NODELET_INFO("map store %s reachable (index revision %s)", status.url.c_str(), status.revision.c_str());
    if (status.reachable != store_reachable_) {
      store_reachable_ = status.reachable;
      publishStatus();
    }
  }

  // With no pose and no hint start/search_timeout after start-up: the whole map, for the localizer's global search.
  void maybeServeWholeMap() {
    const double timeout = config_.start_search_timeout;
    {
      std::lock_guard<std::mutex> lock(input_mutex_);
      if (posed_ || whole_map_tried_ || timeout <= 0.0) return;
    }
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count() < timeout) return;
    const auto start = std::chrono::steady_clock::now();
    std::optional<Served> served;
    double area = 0.0;
    {
      std::lock_guard<std::mutex> lock(server_mutex_);
      if (server_->searching()) return;  // a hint's search is served
      whole_map_tried_ = true;
      area = server_->mapArea();
      if (area <= config_.start_max_area) served = server_->onWholeMap();
    }
    if (area > config_.start_max_area) {
      NODELET_WARN(
          "no pose and no hint %.1f s after start-up, and the map (%.2f km^2) is larger than start/max_area "
          "(%.2f km^2): waiting for initialpose or initialpose_hint",
          timeout, area / 1e6, config_.start_max_area / 1e6);
      return;
    }
    if (!served) return;
    NODELET_WARN("no pose and no hint %.1f s after start-up: serving the whole map (%.2f km^2) for the global search",
                 timeout, area / 1e6);
    publish(*served, start);
  }

  // Serves the window that holds the lost localizer's search region.
  void coverSearch(const LostSearchRegion& region) {
    const auto start = std::chrono::steady_clock::now();
    std::optional<Served> served;
    bool first = false;
    {
      std::lock_guard<std::mutex> lock(server_mutex_);
      first = !server_->searching();
      served = server_->onSearch(region);
    }
    if (!served) return;
    if (first) {
      const TileBox b = served->window.bounds();
      NODELET_WARN("the localizer is lost: the window grows to %.0f m x %.0f m around (%.1f, %.1f) m for its search",
                   (b.i_max - b.i_min + 1) * s_, (b.j_max - b.j_min + 1) * s_, region.x, region.y);
    }
    publish(*served, start);
  }

  // Sends the whole window again when the tile directory was rewritten (new index revision).
  void followDirectory() {
    bool changed = false;
    try {
      std::lock_guard<std::mutex> lock(server_mutex_);
      changed = server_->refresh();
    } catch (const std::exception& e) {
      NODELET_ERROR_THROTTLE(kWarnPeriod, "tile directory unusable, keeping the window as it is: %s", e.what());
      return;
    }
    if (!changed) return;
    NODELET_WARN("tile directory %s changed (index revision %s): sending the whole window again",
                 config_.tiles_dir.c_str(), server_->tiles().revision().c_str());
    broadcastReset();
  }

  void publish(const Served& served, std::chrono::steady_clock::time_point start) {
    const ros::Time stamp = served.pose.t > 0.0 ? ros::Time(served.pose.t) : ros::Time::now();
    std::size_t loaded = 0;
    TileDelta::Ptr msg;
    {
      std::lock_guard<std::mutex> lock(server_mutex_);
      msg = tileDeltaMsg(stamp, served.window, served.first, served.delta.added, served.delta.removed,
                         served.delta.prefetch);
      if (served.changed) {
        msg->revision = ++revision_;
        delta_pub_.publish(msg);
      }
      loaded = server_->tiles().loadedCount();
      if (map_cloud_ && (served.first || !served.delta.added.empty() || !served.delta.removed.empty()))
        map_cloud_->changed(windowPaths(), stamp);
    }
    reportOffMap(served, loaded);
    const double update_ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    last_status_ = providerStatusMsg(*msg, served.window, loaded, update_ms);
    publishStatus();
  }

  // ~status with the map store's state (a change of it alone publishes the last window's status again).
  void publishStatus() {
    if (!last_status_) return;
    if (store_) {
      const MapStoreStatus status = store_->status();
      last_status_->store_reachable = status.reachable;
      last_status_->store_error = status.last_error;
    }
    status_pub_.publish(*last_status_);
  }

  void reportOffMap(const Served& served, std::size_t loaded) {
    const bool off_map = loaded == 0;
    if (off_map) {
      const TileBox w = served.window.bounds();
      const MapExtent m = server_->mapExtent();
      NODELET_WARN_THROTTLE(kWarnPeriod,
                            "pose (%.1f, %.1f) m is off the map: no tile in window i %ld..%ld, j %ld..%ld (the map "
                            "spans x %.0f..%.0f m, y %.0f..%.0f m); publishing an empty window until the pose returns",
                            served.pose.x, served.pose.y, static_cast<long>(w.i_min), static_cast<long>(w.i_max),
                            static_cast<long>(w.j_min), static_cast<long>(w.j_max), m.x_min, m.x_max, m.y_min, m.y_max);
    } else if (off_map_) {
      NODELET_INFO("pose (%.1f, %.1f) m is back on the map: %zu tiles in the window", served.pose.x, served.pose.y,
                   loaded);
    }
    off_map_ = off_map;
  }

  // The window's tile files (server_mutex_ held).
  std::vector<std::string> windowPaths() const {
    std::vector<std::string> paths;
    for (const TileKey& k : server_->tiles().loaded()) paths.push_back(server_->tiles().directory().tilePath(k));
    return paths;
  }

  TileDelta::Ptr tileDeltaMsg(const ros::Time& stamp, const Window& window, bool reset,
                              const std::vector<TileKey>& added, const std::vector<TileKey>& removed,
                              const std::vector<TileKey>& prefetch) const {
    return makeTileDelta(stamp, config_.map_frame, revision_, reset, s_, window, server_->tiles().directory().path,
                         server_->tiles().revision(), added, removed, prefetch);
  }

  // A reset delta of the whole window at the current revision, to one new subscriber.
  void sendReset(const ros::SingleSubscriberPublisher& peer) {
    std::lock_guard<std::mutex> lock(server_mutex_);
    if (!server_) return;
    const auto whole = server_->whole();
    if (whole)
      peer.publish(
          *tileDeltaMsg(ros::Time::now(), whole->first, true, whole->second.added, {}, whole->second.prefetch));
  }

  // A reset delta of the whole window as a new revision to every subscriber; its revision, or nullopt before the
  // first window.
  std::optional<std::uint32_t> broadcastReset() {
    std::lock_guard<std::mutex> lock(server_mutex_);
    if (!server_) return std::nullopt;
    const auto whole = server_->whole();
    if (!whole) return std::nullopt;
    ++revision_;
    delta_pub_.publish(
        tileDeltaMsg(ros::Time::now(), whole->first, true, whole->second.added, {}, whole->second.prefetch));
    if (map_cloud_) map_cloud_->changed(windowPaths(), ros::Time::now());
    return revision_;
  }

  ProviderConfig config_;
  MapStoreConfig store_config_;
  // Worker only: the map store of a tile directory given by URL, and the index it hands to the window.
  std::unique_ptr<MapStore> store_;
  std::shared_ptr<RemoteTileIndex> remote_;
  std::chrono::steady_clock::time_point next_poll_;
  bool store_reachable_ = true;
  std::mutex server_mutex_;  // the window server, the revision, and every publish on tile_delta
  std::optional<WindowServer> server_;
  double s_ = 0.0;  // tile side [m], set with server_
  std::uint32_t revision_ = 0;
  bool off_map_ = false;                       // worker only
  std::optional<ProviderStatus> last_status_;  // worker only: the last ~status published

  std::mutex input_mutex_;  // what the callbacks hand to the worker
  std::condition_variable input_ready_;
  std::optional<PoseSample> latest_;
  std::optional<LostSearchRegion> search_;
  bool tracking_again_ = false;
  bool posed_ = false;  // a pose came (or was saved): hints and the whole-map start no longer apply
  bool stop_ = false;
  bool whole_map_tried_ = false;  // worker only
  const std::chrono::steady_clock::time_point started_ = std::chrono::steady_clock::now();
  std::thread worker_;

  std::unique_ptr<ProviderMapCloud> map_cloud_;
  std::unique_ptr<SavedPoseWriter> saved_pose_;  // ~last_pose
  ros::Publisher delta_pub_, status_pub_;
  ros::Subscriber pose_sub_, initial_pose_sub_, status_sub_, hint_sub_;
  ros::ServiceServer resend_srv_;
};

}  // namespace grid_puzzle_localization

PLUGINLIB_EXPORT_CLASS(grid_puzzle_localization::GridPuzzleProviderNodelet, nodelet::Nodelet)
