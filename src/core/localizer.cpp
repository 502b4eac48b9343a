#include "grid_puzzle_localization/localizer.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

namespace grid_puzzle_localization {
namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// The scan-to-scan odometry that carries a start while its map arrives: the matching's settings on voxels wide enough
// to hold several of the downsampled scan's points (4 leaves a side: a surface crossing one holds about 16), one
// thread (the scan thread's).
NdtConfig startOdometryConfig(const LocalizerConfig& config) {
  NdtConfig c = config.ndt;
  c.resolution = std::max(config.ndt.resolution, 4.0 * config.preprocess.voxel_size);
  c.threads = 1;
  return c;
}

VoxelMapParams workerParams(const LocalizerConfig& config) {
  VoxelMapParams p = config.ndt;
  p.threads = config.map_update_threads;
  return p;
}

const LocalizerConfig& validated(const LocalizerConfig& config) {
  const std::string problem = config.validate();
  if (!problem.empty()) throw std::invalid_argument("localizer parameters: " + problem);
  return config;
}

// Right after a start or a recovery no velocity is measured. When the motion bound keeps the scan within this many
// NDT voxels of the last accepted pose (the coarse stage's basin, with a margin), the match from that pose is tried
// before the branch-and-bound search: 0.2 s after a start at the default max_speed the bound is 4 m.
constexpr double kHeldMatchReachVoxels = 4.0;

// A prediction extrapolated over the time since the last match (a measured velocity, a recovery's last twist) is
// metres off after dropped scans: its match starts on the target's coarse map, whose basin is that much wider, as
// do the hypotheses' candidates (tryHypotheses). A held pose (after a start) is matched without it: a scan taken on
// the move and not yet deskewed is smeared along the motion, and from the held pose the wider basin can settle at the
// far end of the smear, whose velocity the deskewing of the next scans then takes up (test_deskew).
constexpr bool kFromCoarseMap = true;

// After a recovery the velocity measured before the loss carries the last accepted pose to the scan (a car driving
// on through dropped scans). That guess is a bet: when the vehicle turned meanwhile (a search that answers a second
// late, in a sharp turn), it is far off, and its match can run a dozen iterations and more on every such scan while
// the search decides anyway. It gets this many Newton iterations and must converge within them; a carried guess that
// holds converges in two to four (the coarse stage takes it the metres).
constexpr int kCarriedMatchIterations = 6;

// An automatic start holds the answers of this many searches that no later one agreed with yet (the oldest goes):
// on a loaded machine a search takes over a second, and a right answer followed by a wrong one still finds its match.
constexpr std::size_t kHeldStartAnswers = 4;

NdtConfig carriedMatchConfig(const NdtConfig& config) {
  NdtConfig c = config;
  c.max_iterations = std::min(config.max_iterations, kCarriedMatchIterations);
  return c;
}

// Two matches land on different poses: farther apart than `distance` [m], or turned by more than 0.1 rad.
bool distinct(const NdtResult& a, const NdtResult& b, double distance) {
  const Eigen::Isometry3d pa = toIsometry(a.transform), pb = toIsometry(b.transform);
  return (pa.translation() - pb.translation()).norm() > distance ||
         Eigen::AngleAxisd(pa.rotation().transpose() * pb.rotation()).angle() > 0.1;
}

// The pose covariance of an accepted match, in ROS's order and frame.
Matrix6d matchCovariance(const NdtResult& r, const CovarianceConfig& config) {
  const Vector6d p = matrixToPose(r.transform.cast<double>());
  return fixedAxisCovariance(covarianceFromHessian(r.hessian, config), p(3), p(4));
}

// The covariance of a prediction `elapsed` after a match with covariance `last`: that one plus the search
// region's extent (radius on x y z, yaw range on the rotations), at most the max-std diagonal.
Matrix6d coastingCovariance(const Matrix6d& last, const SearchRegion& region, const CovarianceConfig& config) {
  Matrix6d cov = last;
  for (int i = 0; i < 3; ++i) cov(i, i) += region.radius * region.radius;
  for (int i = 3; i < 6; ++i) cov(i, i) += region.yaw_range * region.yaw_range;
  const Matrix6d max = predictionCovariance(config);
  for (int i = 0; i < 6; ++i)
    if (cov(i, i) > max(i, i)) {
      const double s = std::sqrt(max(i, i) / cov(i, i));
      cov.row(i) *= s;
      cov.col(i) *= s;
    }
  return cov;
}

}  // namespace

Localizer::Localizer(const LocalizerConfig& config)
    : config_(validated(config)),
      preprocessor_(config.preprocess),
      aligner_(config.ndt),
      carried_aligner_(carriedMatchConfig(config.ndt)),
      start_odometry_(startOdometryConfig(config), config.match.min_nvtl, config.prediction.max_speed),
      worker_(workerParams(config)),
      fusion_(config.fusion),
      global_(globalSearchConfig(config)) {}

void Localizer::addGyro(double stamp, const Eigen::Vector3d& angular_velocity) {
  if (angular_velocity.allFinite()) gyro_.add(stamp, angular_velocity);
}

void Localizer::addImu(const ImuSample& sample) {
  if (sample.has_gyro) addGyro(sample.stamp, fusion_.baseTImu().rotation() * sample.gyro);
  fusion_.addImu(sample);
}

void Localizer::reset() {
  predictor_ = PosePredictor();
  fusion_.reset();
  gyro_.clear();
  holdStart(default_initial_pose_);
  last_twist_.reset();
  last_stamp_.reset();
  source_stamp_.reset();
  motion_seen_ = MotionBounds();
  start_refused_ = false;
  start_candidates_.clear();
  ++track_version_;
}

bool Localizer::mapHolds(const Eigen::Vector3d& centre, double half) const {
  const MapUpdateStats stats = worker_.stats();
  if (stats.tiles == 0) return true;
  if (const std::optional<MapExtent>& w = stats.window)  // the provider's window: off the map where it has no tile
    return w->holdsSquare(centre.x(), centre.y(), half);
  const std::optional<Eigen::AlignedBox3d> box = mapBounds();
  if (!box) return false;
  // Voxel means lie up to a voxel inside the area the tiles cover.
  const double r = config_.ndt.resolution;
  const MapExtent covered{box->min().x() - r, box->max().x() + r, box->min().y() - r, box->max().y() + r};
  return covered.holdsSquare(centre.x(), centre.y(), half);
}

std::optional<Eigen::AlignedBox3d> Localizer::mapBounds() const {
  if (!target_ || target_->gaussianCount() == 0) return std::nullopt;
  Eigen::AlignedBox3d box;
  target_->forEach([&](const VoxelKey&, const VoxelStats&, const auto& gaussian) {
    if (gaussian.valid) box.extend(gaussian.mean.template cast<double>());
  });
  return box;
}

std::optional<Eigen::Isometry3d> Localizer::lastAcceptedPose() const {
  if (!predictor_.initialized()) return std::nullopt;
  return predictor_.pose();
}

GlobalLocalizationResult Localizer::searchGlobally(const GlobalSearchRequest& request) {
  GlobalLocalizationResult r;
  if (!target_ || target_->gaussianCount() == 0) {
    r.reason = "no map yet";
    return r;
  }
  if (!source_stamp_) {
    r.reason = "no scan yet";
    return r;
  }
  return runSearch(target_, source_, request);
}

GlobalSearchRequest Localizer::searchRequest(const SearchRegion& region, int threads) const {
  GlobalSearchRequest request;
  request.threads = threads;
  request.center_x = region.centre.translation().x();
  request.center_y = region.centre.translation().y();
  request.size = std::max(2.0 * region.radius, 2.0 * config_.ndt.resolution);
  request.yaw_center = std::atan2(region.centre.linear()(1, 0), region.centre.linear()(0, 0));
  // A known rotation is still searched over a few steps either side: the search's answer is refined by NDT.
  request.yaw_range =
      region.yaw_range >= M_PI ? 2.0 * M_PI : 2.0 * std::max(region.yaw_range, config_.hypotheses.yaw_step);
  return request;
}

GlobalLocalizationResult Localizer::runSearch(const std::shared_ptr<const VoxelMap>& target, const PointCloud& source,
                                              const GlobalSearchRequest& request) {
  if (global_target_ != target) {
    // The search's map is the target's voxel means (what the localizer holds of the map), refined on the target.
    PointCloud means;
    means.reserve(target->gaussianCount());
    target->forEach([&](const VoxelKey&, const VoxelStats&, const VoxelGaussian& g) {
      if (!g.valid) return;
      means.push_back(g.mean);
    });
    global_.setMap(means, target);
    global_target_ = target;
  }
  GlobalLocalizationResult r = global_.localize(source, request);
  if (r.found && !acceptable(r.refinement)) {
    r.found = false;
    r.reason = "the refined pose fails the match gate (match/*)";
  }
  return r;
}

void Localizer::waitForSearch() const {
  if (search_) search_->result.wait();
}

void Localizer::startBackgroundSearch(double stamp, const SearchRegion& region, bool restarts_track,
                                      const Reach& reach) {
  BackgroundSearch job;
  job.stamp = stamp;
  job.track_version = track_version_;
  job.restarts_track = restarts_track;
  job.reach = reach;
  job.result = std::async(std::launch::async, [this, target = target_, source = source_, region] {
    return runSearch(target, source, searchRequest(region));
  });
  search_ = std::move(job);
  last_global_search_ = stamp;
}

std::optional<double> Localizer::takeFinishedSearch(double stamp, LocalizerOutput& out) {
  if (!search_ || search_->result.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return std::nullopt;
  BackgroundSearch job = std::move(*search_);
  search_.reset();
  const GlobalLocalizationResult g = job.result.get();
  releaseStaleSearchMap();
  // The track moved on (a start search's answer is a start's: stale once tracking).
  if (job.start || job.track_version != track_version_ || !predictor_.initialized()) return std::nullopt;
  out.global_search = true;
  out.global_search_reason = g.reason;
  if (!g.found || !job.reach.holds(g.map_T_base)) return std::nullopt;
  const double lost_for = stamp - predictor_.stamp();
  if (job.restarts_track) {
    predictor_.reset(g.map_T_base, job.stamp);
    fusion_.reset();  // the window starts again at the pose found
  } else {
    predictor_.update(g.map_T_base, job.stamp, config_.preprocess.deskew_twist_smoothing);
  }
  noteAccepted(g.refinement);
  return lost_for;
}

void Localizer::releaseStaleSearchMap() {
  if (global_target_ && global_target_ != target_) {
    // Built for a target swapped out while the search ran: released now, as at the swap.
    global_.clearMap();
    worker_.retire(std::move(global_target_));
  }
}

void Localizer::noteAccepted(const NdtResult& match) {
  if (predictor_.twistMeasured()) {
    motion_seen_.add(predictor_.twist());
    last_twist_ = predictor_.twist();
  }
  last_covariance_ = matchCovariance(match, config_.covariance);
  reference_nvtl_ = match.nvtl;
  start_refused_ = false;
  ++track_version_;
}

GlobalLocalizationResult Localizer::searchLastScan(const GlobalSearchRequest& request) {
  if (search_) {  // a background search's answer would come after this one's: it is not waited for
    search_->result.wait();
    search_.reset();
  }
  return searchGlobally(request);
}

void Localizer::startFromSearch(const GlobalLocalizationResult& found) {
  // The pose of the last scan, at its stamp: the next scans search around it with a radius that grows with
  // the time since (the vehicle may move while the search runs), as after any pose without a velocity.
  startFrom(found.map_T_base, *source_stamp_, matchCovariance(found.refinement, config_.covariance),
            found.refinement.nvtl);
  fusion_.reset();  // the next scan starts a new window at the pose found
}

GlobalLocalizationResult Localizer::globalLocalize(const SearchRegion& region) {
  GlobalLocalizationResult r = searchLastScan(searchRequest(region));
  if (r.found) startFromSearch(r);
  return r;
}

StartSearch Localizer::judgeStart(GlobalLocalizationResult r, double stamp) {
  if (!r.found) return {r, false};
  const StartCandidate answer{r.map_T_base, stamp};
  // The latest held answer that this one agrees with (a search between them may have answered elsewhere).
  for (auto earlier = start_candidates_.rbegin(); earlier != start_candidates_.rend(); ++earlier) {
    const SearchRegion reach =
        boundedSearchRegion(earlier->pose, answer.stamp - earlier->stamp, MotionBounds(), false, config_.prediction);
    const double apart = (answer.pose.translation() - earlier->pose.translation()).head<2>().norm();
    const double turn = Eigen::AngleAxisd(earlier->pose.rotation().transpose() * answer.pose.rotation()).angle();
    if (apart > reach.radius + config_.global.runner_up_distance ||
        turn > reach.yaw_range + config_.global.runner_up_yaw)
      continue;
    // The two answers also measure the motion between their scans: the next scan is predicted from it, as in
    // tracking, instead of being searched for around a pose without a velocity.
    startFrom(earlier->pose, earlier->stamp, matchCovariance(r.refinement, config_.covariance), r.refinement.nvtl);
    predictor_.update(answer.pose, answer.stamp, config_.preprocess.deskew_twist_smoothing);
    noteAccepted(r.refinement);
    fusion_.reset();
    return {r, false};
  }
  r.found = false;
  r.reason = start_candidates_.empty()
                 ? "held until the search of a later scan agrees (one search's answer alone is not taken)"
                 : "another place than the held answers: held until the search of a later scan agrees";
  if (start_candidates_.size() == kHeldStartAnswers) start_candidates_.erase(start_candidates_.begin());
  start_candidates_.push_back(answer);
  return {r, true};
}

void Localizer::startFrom(const Eigen::Isometry3d& pose, double stamp, const Matrix6d& covariance,
                          double reference_nvtl) {
  pending_initial_pose_.reset();
  predictor_.reset(pose, stamp);
  last_twist_.reset();
  motion_seen_ = MotionBounds();
  last_covariance_ = covariance;
  reference_nvtl_ = reference_nvtl;
  last_global_search_.reset();
  start_refused_ = false;
  start_candidates_.clear();
  ++track_version_;
}

std::optional<NdtResult> Localizer::tryHypotheses(const Eigen::Isometry3d& guess, const Eigen::Isometry3d& held,
                                                  bool rotation_known, LocalizerOutput& out) {
  // Yaw offsets around the prediction and around the last accepted pose (a swing that reverses lands between
  // them), screened by the NDT cost; the best few are aligned. With a known rotation: the last pose only.
  SearchRegion around;
  around.yaw_range = rotation_known ? 0.0 : config_.hypotheses.yaw_step * config_.hypotheses.yaw_count;
  SearchConfig screen;
  screen.yaw_step = config_.hypotheses.yaw_step;
  screen.screen_points = config_.hypotheses.screen_points;
  screen.refine = config_.hypotheses.refine;
  std::vector<Eigen::Isometry3d> guesses;
  for (const Eigen::Isometry3d* centre : {&held, &guess}) {
    if (rotation_known && centre == &guess) continue;
    around.centre = *centre;
    for (const Eigen::Isometry3d& g : searchCandidates(around, screen))
      if (!g.isApprox(guess, 1e-9)) guesses.push_back(g);  // the prediction itself was matched already
  }
  std::vector<Eigen::Isometry3d> starts = screenCandidates(aligner_, *target_, source_, guesses, screen);
  // With a coarse stage, each candidate is aligned on the subsample only, the whole scan scores where each landed, and
  // the best alone is aligned in full: one full alignment instead of one per candidate. A candidate keeps the
  // prediction's or the last pose's position, metres from the pose when the prediction is, so its coarse stage starts
  // on the coarse map: from the fine map alone it could stop metres short, where the full alignment then ran to
  // max_iterations (test_ndt_real).
  // A candidate at the position of one whose coarse stage ran, and within that stage's yaw probe of it, is skipped:
  // the stage started from the best of that one turned either way (the best-screened candidates are often neighbouring
  // yaw offsets at the last pose, all descending into one basin, metres away on a car).
  std::optional<Eigen::Isometry3d> best_start;
  double best_cost = std::numeric_limits<double>::infinity();
  std::vector<Eigen::Isometry3d> descended;
  for (const Eigen::Isometry3d& g : starts) {
    if (std::any_of(descended.begin(), descended.end(), [&](const Eigen::Isometry3d& d) {
          return coveredByYawProbe(d, g, 0.5 * screen.step, aligner_.config().coarse_yaw_probe);
        }))
      continue;
    const std::optional<Eigen::Isometry3d> coarse = aligner_.coarseAlign(*target_, source_, g, kFromCoarseMap);
    if (!coarse) break;  // no coarse stage for this scan: every candidate is aligned in full
    descended.push_back(g);
    const double cost = aligner_.derivatives(*target_, source_, matrixToPose(coarse->matrix())).cost;
    if (cost < best_cost) {
      best_cost = cost;
      best_start = coarse;
    }
  }
  out.hypotheses = static_cast<int>(best_start ? descended.size() : starts.size());
  if (best_start) starts = {*best_start};
  std::optional<NdtResult> best;
  for (const Eigen::Isometry3d& g : starts) {
    NdtResult r = aligner_.align(*target_, source_, g.cast<float>());
    if (acceptable(r) && (!best || r.nvtl > best->nvtl)) best = std::move(r);
  }
  return best;
}

bool Localizer::acceptable(const NdtResult& r) const {
  if (r.status != NdtResultStatus::OK && r.status != NdtResultStatus::MAX_ITERATIONS) return false;
  if (config_.match.require_converged && !r.converged) return false;
  if (r.nvtl < config_.match.min_nvtl) return false;
  if (r.transformation_probability < config_.match.min_transformation_probability) return false;
  return r.transform.allFinite();
}

SweepMotion Localizer::sweepMotion(double stamp, double t_begin, double t_end, const Eigen::Isometry3d& base_T_sensor,
                                   bool velocity_unknown, const std::optional<FusedState>& fused) const {
  // Without a velocity (right after an initial pose, after a gap) the sensor is taken to stand still but for the
  // rotation the gyro measured over the sweep.
  Twist twist = velocity_unknown ? Twist::Zero() : predictor_.smoothedTwist();
  if (fused && !velocity_unknown) twist.head<3>() = fused->pose.rotation().transpose() * fused->velocity;
  if (!config_.imu.use_gyro || !gyro_.covers(stamp + t_begin, stamp + t_end, config_.imu.max_gap))
    return SweepMotion::fromTwist(twist, base_T_sensor, t_begin, t_end);
  auto rotation = [&](double t) {
    return t >= 0.0 ? gyro_.integrate(stamp, stamp + t) : gyro_.integrate(stamp + t, stamp).inverse();
  };
  auto motion = [&](double t) {
    Eigen::Isometry3d m = expTwist(twist, t);
    m.linear() = rotation(t).toRotationMatrix();
    return m;
  };
  const double span = t_end - t_begin;
  const double rate =
      span > 0.0 ? Eigen::AngleAxisd(rotation(t_begin).inverse() * rotation(t_end)).angle() / span : 0.0;
  return SweepMotion(motion, base_T_sensor, t_begin, t_end, std::max(rate, twist.tail<3>().norm()));
}

LocalizerOutput Localizer::processScan(double stamp, const PointCloud& scan, const Eigen::Isometry3d& base_T_sensor,
                                       const PointTimes* times) {
  const Clock::time_point start = Clock::now();
  LocalizerOutput out;
  if (last_stamp_ && stamp < *last_stamp_ - config_.time_jump_back) {
    reset();
    out.reset = true;
  }
  last_stamp_ = stamp;
  out.map_update_pending = worker_.busy();
  std::optional<MapSnapshot> next = worker_.takeSnapshot();
  if (next) in_flight_ = std::move(next->in_flight);
  if (next && next->map) {
    // The old snapshot may hold the last reference to thousands of voxel buffers: the worker frees them.
    worker_.retire(std::exchange(target_, std::move(next->map)));
    out.map_swapped = true;
    if (global_target_ && !search_) {
      // The search structures of an older target would be rebuilt before the next search anyway, and they hold
      // that target alive (in tiles mode a whole window that has moved on): release both now.
      global_.clearMap();
      worker_.retire(std::move(global_target_));
    }
  }
  if (target_) {
    out.target_voxels = target_->gaussianCount();
    out.target_points = target_->pointCount();
  }
  out.tiles_in_flight = in_flight_.keys.size();
  // A given pose is matched from once the tiles around it have arrived: a partial map could fit the scan elsewhere. It
  // is matched moved on to this scan by its carried velocity (from its last scan to this one): the tiles around that
  // place.
  std::optional<Eigen::Isometry3d> given_start;
  if (pending_initial_pose_) {
    given_start = *pending_initial_pose_ * start_odometry_.motionTo(stamp);
    out.tiles_awaited = tilesAwaited(given_start->translation().head<2>(), config_.map_wait_half_side);
  }
  if (!target_ || target_->gaussianCount() == 0 || out.tiles_awaited > 0) {
    // The vehicle may drive on meanwhile: the start goes with it.
    if (pending_initial_pose_) {
      prepareUndeskewed(scan, base_T_sensor, stamp, out);
      carryStart(stamp, out);
    }
    out.state = LocalizerState::kWaitingForMap;
    out.scan_ms = msSince(start);
    return out;
  }
  const bool fresh = given_start.has_value();
  if (fresh) {
    startFrom(*given_start, stamp, predictionCovariance(config_.covariance), 0.0);
    // Its motion is the vehicle's: the next scan is matched from the start moved on by it first, as after a recovery.
    if (!start_odometry_.velocity().isZero()) last_twist_ = start_odometry_.velocity();
  }
  // A start search beside the scan thread that has finished is judged; a confirmed answer starts the track, and this
  // scan is matched from it.
  if (!predictor_.initialized()) out.start_search = takeStartSearch();
  if (!predictor_.initialized()) {
    // Kept (not deskewed: no motion is known) for a global search started while waiting.
    prepareUndeskewed(scan, base_T_sensor, stamp, out);
    out.state = LocalizerState::kWaitingForInitialPose;
    out.scan_ms = msSince(start);
    return out;
  }
  out.state = LocalizerState::kTracking;
  // A background search that has finished answers for the scan it searched; its pose, taken up, is that scan's match.
  const std::optional<double> lost_for = takeFinishedSearch(stamp, out);
  const bool search_refused = out.global_search && !lost_for;
  // The predictor holds the last accepted pose. Its velocity is extrapolated only when it was measured and
  // the last match is recent; else the pose is searched around the last accepted one.
  const double elapsed = stamp - predictor_.stamp();
  const bool velocity_trusted =
      predictor_.twistMeasured() && elapsed >= 0.0 && elapsed <= config_.prediction.max_extrapolation;

  // With the window, its IMU-propagated state is the prediction (while the window holds a recent state).
  const std::optional<FusedState> fused_prediction =
      !fresh && elapsed <= config_.prediction.max_extrapolation ? fusion_.predict(stamp) : std::nullopt;
  if (config_.preprocess.deskew && times && times->size() == scan.size()) {
    const auto [t_begin, t_end] = timeSpan(*times);
    const SweepMotion motion =
        sweepMotion(stamp, t_begin, t_end, base_T_sensor, fresh || !velocity_trusted, fused_prediction);
    preprocessor_.apply(scan, source_, &out.preprocess, times, &motion);
  } else {
    preprocessor_.apply(scan, source_, &out.preprocess);
  }
  const Eigen::Isometry3f base_T_sensor_f = base_T_sensor.cast<float>();
  for (Point& p : source_) p = base_T_sensor_f * p;
  source_stamp_ = stamp;

  std::optional<Eigen::Quaterniond> gyro_rotation;
  if (!fresh && config_.imu.use_gyro && gyro_.covers(predictor_.stamp(), stamp, config_.imu.max_gap))
    gyro_rotation = gyro_.integrate(predictor_.stamp(), stamp);
  const bool rotation_known = gyro_rotation.has_value();
  // The last accepted pose, turned by the gyro when it covers the time since.
  Eigen::Isometry3d held = predictor_.pose();
  if (gyro_rotation) held.linear() = predictor_.pose().linear() * gyro_rotation->toRotationMatrix();
  const Eigen::Isometry3d guess = fused_prediction ? fused_prediction->pose
                                  : velocity_trusted
                                      ? predictor_.predict(stamp, gyro_rotation ? &*gyro_rotation : nullptr)
                                      : held;
  const SearchRegion region =
      boundedSearchRegion(held, fresh ? 0.0 : elapsed, motion_seen_, rotation_known, config_.prediction);

  out.prediction = guess;
  // The map under the scan is still arriving (a slow map store the vehicle outran): a match on the part that has
  // arrived can slide along where the rest is missing and still pass the gate. The track waits instead, carried like
  // a start by the scans' own motion from this scan on, and is matched where the vehicle is once those tiles are in.
  if (!fresh) {
    const std::size_t ahead = tilesAwaited(guess.translation().head<2>(), config_.map_wait_half_side);
    if (ahead > 0) {
      // Carried from where the vehicle is: the prediction, or right after a start or a recovery (no velocity measured
      // yet) the last accepted pose moved on by the last measured motion, which the start's own carry measured.
      const bool carried = !velocity_trusted && last_twist_;
      holdStart(carried ? Eigen::Isometry3d(predictor_.pose() * expTwist(*last_twist_, elapsed)) : guess,
                velocity_trusted ? predictor_.smoothedTwist() : last_twist_.value_or(Twist::Zero()));
      waitForMapCarried(stamp, ahead, out);
      out.scan_ms = msSince(start);
      return out;
    }
  }
  const Clock::time_point align_start = Clock::now();
  // A match is poor when it fails the gate or scores well below the last accepted one (a false minimum
  // can pass an absolute gate): then the hypotheses and, failing them, the search get a chance.
  auto poor = [&](const NdtResult& r) {
    return !acceptable(r) || r.nvtl < config_.hypotheses.poor_nvtl_ratio * reference_nvtl_;
  };
  // The bounded region (the fastest motion seen, or max_speed before any), and a voxel for the match's basin.
  const Reach reach{held.translation().head<2>(), region.radius + config_.ndt.resolution};
  std::optional<NdtResult> best;
  auto consider = [&](std::optional<NdtResult> r) {
    if (r && acceptable(*r) && reach.holds(toIsometry(r->transform)) && (!best || r->nvtl > best->nvtl))
      best = std::move(r);
  };
  if (fresh && !start_motion_guessed_) {
    // A pose given by the user (rviz, a parameter) is matched from as given (carried by the scans' own motion while
    // its map arrived), the search only when that fails. When that motion was not measured throughout (scans that did
    // not match each other), the start is not known to the NDT's reach: the search of its square decides.
    out.ndt = aligner_.align(*target_, source_, guess.cast<float>());
    consider(out.ndt);
  } else if (velocity_trusted) {
    out.ndt = aligner_.align(*target_, source_, guess.cast<float>(), kFromCoarseMap);
    if (!poor(out.ndt)) {
      consider(out.ndt);
    } else {
      // A poor match may be a false minimum (a hand-held swing reversing between scans without a gyro) or the
      // scene may just have changed (real scans overlap the map unevenly). The hypotheses tell them apart: a
      // distinct pose that fits better is taken when it fits as well as the track did, and refuses the
      // prediction's match either way; when none fits better, the prediction's match stands.
      std::optional<NdtResult> alternative = tryHypotheses(guess, held, rotation_known, out);
      const bool better_elsewhere =
          alternative && alternative->nvtl > out.ndt.nvtl && distinct(*alternative, out.ndt, config_.ndt.resolution);
      if (!better_elsewhere) consider(out.ndt);
      if (alternative && (!better_elsewhere || !poor(*alternative))) consider(std::move(alternative));
    }
  }
  // Before a velocity is measured (the scans after a start or a recovery) the match from the last accepted pose is
  // taken when it fits as well as the track did and the motion bound keeps the scan within the NDT's reach of that
  // pose; the search runs when it does not (a scene that fits many places, a fast start, scans far apart).
  const bool long_gap = !fresh && elapsed > config_.prediction.max_extrapolation;
  // A given pose that its first scan refused is not matched from again (a match near it may pass the gate yet be
  // wrong): until a pose is accepted, only the search places the scans.
  const bool velocity_unmeasured = !fresh && !velocity_trusted && !long_gap && elapsed >= 0.0 && !start_refused_;
  // After a recovery the vehicle most likely still moves as it did before it: the match from the last accepted pose
  // moved on by the last measured twist is tried first, under the same gate. Not while a background search runs: the
  // search was started because nothing fitted from this pose, and it decides.
  if (velocity_unmeasured && last_twist_ && !search_) {
    Eigen::Isometry3d carried = predictor_.pose() * expTwist(*last_twist_, elapsed);
    if (gyro_rotation) carried.linear() = held.linear();
    out.ndt = carried_aligner_.align(*target_, source_, carried.cast<float>(), kFromCoarseMap);
    if (out.ndt.converged && !poor(out.ndt)) consider(out.ndt);
  }
  const bool held_first =
      !best && velocity_unmeasured && region.radius <= kHeldMatchReachVoxels * config_.ndt.resolution;
  if (held_first) {
    out.ndt = aligner_.align(*target_, source_, guess.cast<float>());
    if (!poor(out.ndt)) consider(out.ndt);
  }
  // No trusted prediction (start-up, a gap, a loss) or nothing fitted from it: the branch-and-bound search of the
  // bounded region (every yaw after a gap when the rotation is not known), at most once per search_period. A given
  // pose that the scan does not fit is wrong: once the map held reaches around it, the square of
  // lost/initial_pose_search_size around it is searched at once, every yaw.
  // The map of a given start is still loading: the window's change in progress, or its tiles in flight around the
  // start's search square. The start is then tried again at the next scan, not searched from.
  const double start_half = 0.5 * config_.lost.initial_pose_search_size;
  const std::size_t start_awaited =
      fresh ? tilesAwaited(held.translation().head<2>(), std::max(start_half, config_.map_wait_half_side)) : 0;
  const bool start_map_loading = fresh && (out.map_update_pending || worker_.busy() || start_awaited > 0);
  // Tiles still in flight around the pose or in its bounded region: a failed match or a search there waits for them
  // (on a partial map a search is ambiguous, or finds a look-alike place) and is not lost.
  const std::size_t awaited =
      tilesAwaited(held.translation().head<2>(), std::max(config_.map_wait_half_side, region.radius));
  const bool search_due = !long_gap || !last_global_search_ ||
                          stamp - *last_global_search_ >= config_.lost.search_period || stamp < *last_global_search_;
  std::optional<Eigen::Isometry3d> found_globally;
  if ((!best || poor(*best)) && search_due && !search_ && !search_refused && awaited == 0) {
    SearchRegion wide = region;
    if (long_gap && !rotation_known) wide.yaw_range = M_PI;
    // The square around a wrong start bounds where the pose is; no motion since it bounds it further.
    const bool start_search =
        fresh && !start_map_loading && start_half > 0.0 && mapHolds(held.translation(), start_half);
    if (start_search) {
      wide.radius = std::max(wide.radius, start_half);
      wide.yaw_range = M_PI;
    }
    if (!config_.lost.background_search) {
      GlobalLocalizationResult g = searchGlobally(searchRequest(wide));
      last_global_search_ = stamp;
      out.global_search = true;
      out.global_search_reason = g.reason;
      if (g.found && (start_search || reach.holds(g.map_T_base))) {
        best = g.refinement;
        found_globally = g.map_T_base;
      }
    } else if (!start_map_loading) {  // a start whose map is loading is tried again, not searched from
      startBackgroundSearch(stamp, wide, fresh || long_gap, start_search ? Reach{} : reach);
      out.search_started = true;
    }
  }
  // With a background search running the search decides; the match from the last accepted pose is tried once it
  // has refused.
  if (!best && velocity_unmeasured && !held_first && (search_refused || !search_)) {
    // Farther than the NDT's reach the search decides. When it refuses a scene as ambiguous (a tunnel fits many places
    // along itself), the match from the last accepted pose is still tried, and taken when it fits as well as the
    // track did.
    out.ndt = aligner_.align(*target_, source_, guess.cast<float>());
    if (!poor(out.ndt)) consider(out.ndt);
  }
  if (best) {
    out.ndt = std::move(*best);
    out.match_accepted = true;
  }
  out.align_ms = msSince(align_start);  // with the hypotheses and the search
  if (out.match_accepted) {
    out.pose = found_globally ? *found_globally : toIsometry(out.ndt.transform);
    if (!out.pose.matrix().allFinite()) out.match_accepted = false;
  }
  if (!out.match_accepted && start_map_loading) {
    // The map around a new initial pose may still be loading (a window of tiles arrives over the first scans): the
    // pose is kept for the next scan instead of being searched from as a lost track.
    pending_initial_pose_ = given_start;
    waitForMapCarried(stamp, start_awaited, out);
    out.scan_ms = msSince(start);
    return out;
  }
  if (!out.match_accepted) out.tiles_awaited = awaited;
  out.lost = !out.match_accepted && awaited == 0;
  if (fresh && out.lost) start_refused_ = true;
  if (fresh && (out.match_accepted || out.lost)) holdStart(std::nullopt);  // the start is taken or refused
  if (out.lost) out.search_region = region;
  out.since_last_match = fresh ? 0.0 : elapsed;
  if (out.match_accepted) {
    if (lost_for) out.since_last_match = *lost_for;  // the time without a match that the search ended
    out.recovered = !fresh && out.since_last_match > config_.lost.max_coast_time;
    // A pose found after a gap is a correction, not a motion to extrapolate: the velocity is measured again
    // from the next match. Within max_extrapolation of the last match it measures the motion like any match.
    if (fresh || (found_globally && long_gap))
      predictor_.reset(out.pose, stamp);
    else
      predictor_.update(out.pose, stamp, config_.preprocess.deskew_twist_smoothing);
    noteAccepted(out.ndt);
    out.covariance = last_covariance_;
    out.twist_covariance = predictor_.twistMeasured() && elapsed > 0.0
                               ? bodyFrameCovariance(out.covariance, out.pose.rotation()) * (2.0 / (elapsed * elapsed))
                               : predictionCovariance(config_.covariance);
  } else {
    // The bounded prediction: extrapolated while the velocity is trusted, else held at the last pose.
    out.pose = guess;
    out.covariance = coastingCovariance(last_covariance_, region, config_.covariance);
    out.twist_covariance = predictionCovariance(config_.covariance);
  }
  if (fusion_.enabled()) {
    // A new start or a jump found by the search after a gap begins a new window; the fused state replaces the match.
    const std::optional<Eigen::Isometry3d> fused = fusion_.update(
        stamp, fresh || (found_globally && long_gap), out.match_accepted ? &out.pose : nullptr,
        out.match_accepted ? fusion_.ndtCovariance(out.ndt.hessian, config_.covariance) : Matrix6d::Zero());
    if (fused) out.pose = *fused;
  }
  // A scan that no pose fits contradicts the prediction; only a gyro still measures the heading then. Without
  // one the predicted yaw is a guess (a hand-held swing reverses between scans, and poses sampled a swing period
  // apart show no turn at all to bound it), so the prediction is not published.
  out.publish = out.match_accepted || (rotation_known && out.since_last_match <= config_.lost.max_coast_time);
  out.twist = predictor_.twist();
  // Samples since the last accepted pose are kept while they can still serve a prediction from it.
  gyro_.dropBefore(std::max(predictor_.stamp(), stamp - config_.prediction.max_extrapolation));
  if (config_.output_aligned) {
    const Eigen::Isometry3f map_T_base = out.pose.cast<float>();
    out.aligned.reserve(source_.size());
    for (const Point& p : source_) out.aligned.push_back(map_T_base * p);
  }
  // Tiles still loading go nearest the pose the next scans will be matched around first.
  worker_.setFocus(out.prediction.translation().head<2>());
  out.scan_ms = msSince(start);
  return out;
}

}  // namespace grid_puzzle_localization
