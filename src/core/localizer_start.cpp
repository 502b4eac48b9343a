// The localizer's start: a given pose held (and carried by the scans' own motion) while its map arrives, and the
// search for a start on the scan thread or beside it. The rest of Localizer is in localizer.cpp.
#include <chrono>
#include <string>
#include <utility>

#include "grid_puzzle_localization/localizer.hpp"
#include "thread_priority.hpp"

namespace grid_puzzle_localization {
namespace {

// A start search beside the scan thread runs this much nicer than it (its OpenMP team too).
constexpr int kStartSearchNiceIncrement = 10;

}  // namespace

void Localizer::setInitialPose(const Eigen::Isometry3d& map_T_base) { holdStart(map_T_base); }

void Localizer::setDefaultInitialPose(const Eigen::Isometry3d& map_T_base) {
  default_initial_pose_ = map_T_base;
  if (!predictor_.initialized()) holdStart(map_T_base);
}

void Localizer::holdStart(const std::optional<Eigen::Isometry3d>& map_T_base, const Twist& velocity) {
  pending_initial_pose_ = map_T_base;
  start_odometry_.reset(velocity);
  start_motion_guessed_ = false;
  if (map_T_base) worker_.setFocus(map_T_base->translation().head<2>());  // its tiles first
}

void Localizer::prepareUndeskewed(const PointCloud& scan, const Eigen::Isometry3d& base_T_sensor, double stamp,
                                  LocalizerOutput& out) {
  preprocessor_.apply(scan, source_, &out.preprocess);
  const Eigen::Isometry3f base_T_sensor_f = base_T_sensor.cast<float>();
  for (Point& p : source_) p = base_T_sensor_f * p;
  source_stamp_ = stamp;
}

void Localizer::carryStart(double stamp, LocalizerOutput& out) {
  OdometryStep step = OdometryStep::kFirst;
  const Eigen::Isometry3d motion = start_odometry_.add(stamp, source_, &step);
  *pending_initial_pose_ = *pending_initial_pose_ * motion;
  start_motion_guessed_ = start_motion_guessed_ || step == OdometryStep::kGuessed;
  out.prediction = *pending_initial_pose_;
  out.start_pending = true;
  out.start_motion_guessed = start_motion_guessed_;
  worker_.setFocus(out.prediction.translation().head<2>());
}

void Localizer::waitForMapCarried(double stamp, std::size_t awaited, LocalizerOutput& out) {
  predictor_ = PosePredictor();
  ++track_version_;
  carryStart(stamp, out);
  out.state = LocalizerState::kWaitingForMap;
  out.tiles_awaited = awaited;
}

Localizer::StartSearch Localizer::searchForStart(const SearchRegion& region) {
  // Nothing is tracked while a start is searched for: the search takes every core.
  GlobalLocalizationResult r = searchLastScan(searchRequest(region, 0));
  return judgeStart(std::move(r), source_stamp_.value_or(0.0));
}

std::optional<StartSearch> Localizer::startSearchForStart(const SearchRegion& region) {
  // On a window still arriving the search would call the place ambiguous, or find a look-alike: it waits.
  if (const std::size_t awaited = tilesAwaited(region.centre.translation().head<2>(), region.radius)) {
    StartSearch waiting;
    waiting.tiles_awaited = awaited;
    waiting.search.reason = "waits for " + std::to_string(awaited) + " tiles of its region still loading";
    return waiting;
  }
  if (!config_.lost.background_search) return searchForStart(region);
  if (search_) return std::nullopt;
  if (!target_ || target_->gaussianCount() == 0 || !source_stamp_) {
    StartSearch none;
    none.search.reason = source_stamp_ ? "no map yet" : "no scan yet";
    return none;
  }
  BackgroundSearch job;
  job.stamp = *source_stamp_;
  job.track_version = track_version_;
  job.start = true;
  // Every core, as searchForStart, but below the scan thread: the scans that come meanwhile are not held back by it.
  job.result =
      std::async(std::launch::async, [this, target = target_, source = source_, request = searchRequest(region, 0)] {
        lowerCallingThreadPriority(kStartSearchNiceIncrement);
        return runSearch(target, source, request);
      });
  search_ = std::move(job);
  return std::nullopt;
}

std::optional<StartSearch> Localizer::takeStartSearch() {
  if (!search_ || !search_->start || search_->result.wait_for(std::chrono::seconds(0)) != std::future_status::ready)
    return std::nullopt;
  BackgroundSearch job = std::move(*search_);
  search_.reset();
  GlobalLocalizationResult g = job.result.get();
  releaseStaleSearchMap();
  if (job.track_version != track_version_ || predictor_.initialized()) return std::nullopt;  // a pose came meanwhile
  return judgeStart(std::move(g), job.stamp);
}

}  // namespace grid_puzzle_localization
