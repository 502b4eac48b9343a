#include "grid_puzzle_localization/fusion/sliding_window.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <unordered_map>

#include "grid_puzzle_localization/fusion/factors.hpp"
#include "grid_puzzle_localization/matrix6.hpp"

namespace grid_puzzle_localization {

struct SlidingWindow::State {
  double stamp = 0.0;
  double pose[kPoseSize] = {0, 0, 0, 0, 0, 0, 1};
  double speed_bias[kSpeedBiasSize] = {0, 0, 0, 0, 0, 0, 0, 0, 0};

  Eigen::Map<Eigen::Vector3d> position() { return Eigen::Map<Eigen::Vector3d>(pose); }
  Eigen::Map<Eigen::Quaterniond> rotation() { return Eigen::Map<Eigen::Quaterniond>(pose + 3); }
  Eigen::Map<Eigen::Vector3d> velocity() { return Eigen::Map<Eigen::Vector3d>(speed_bias); }
  Eigen::Quaterniond rotation() const { return Eigen::Quaterniond(pose[6], pose[3], pose[4], pose[5]); }
  Eigen::Vector3d velocity() const { return Eigen::Vector3d(speed_bias[0], speed_bias[1], speed_bias[2]); }
  ImuBias bias() const {
    ImuBias b;
    b.gyro = Eigen::Vector3d(speed_bias[3], speed_bias[4], speed_bias[5]);
    b.accel = Eigen::Vector3d(speed_bias[6], speed_bias[7], speed_bias[8]);
    return b;
  }
};

struct SlidingWindow::Factor {
  std::shared_ptr<ceres::CostFunction> cost;
  std::vector<double*> blocks;
};

/// The IMU between two stamps: the preintegration and what the samples said about it.
struct SlidingWindow::Interval {
  ImuPreintegration pre;
  double gap = 0.0;         ///< [s] bridged without samples
  bool stationary = false;  ///< samples say the robot did not move (see config zupt_*)
};

namespace {

double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// A gap is integrated in steps of at most this length [s], so the gravity direction follows the rotation.
constexpr double kGapStep = 0.01;

}  // namespace

std::string SlidingWindowConfig::validate() const {
  std::ostringstream err;
  auto positive = [&err](const char* name, double v, const char* unit) {
    if (!(v > 0.0) || !std::isfinite(v)) err << name << " must be > 0 " << unit << " (got " << v << "); ";
  };
  positive("gravity", gravity, "m/s^2");
  positive("gyro_noise_density", gyro_noise_density, "rad/s/sqrt(Hz)");
  positive("accel_noise_density", accel_noise_density, "m/s^2/sqrt(Hz)");
  positive("gyro_random_walk", gyro_random_walk, "rad/s^2/sqrt(Hz)");
  positive("accel_random_walk", accel_random_walk, "m/s^3/sqrt(Hz)");
  positive("max_imu_gap", max_imu_gap, "s");
  positive("gap_accel_density", gap_accel_density, "m/s^2/sqrt(Hz)");
  positive("gap_gyro_density", gap_gyro_density, "rad/s/sqrt(Hz)");
  positive("initial_velocity_std", initial_velocity_std, "m/s");
  positive("initial_gyro_bias_std", initial_gyro_bias_std, "rad/s");
  positive("initial_accel_bias_std", initial_accel_bias_std, "m/s^2");
  positive("zupt_max_gyro", zupt_max_gyro, "rad/s");
  positive("zupt_max_accel_std", zupt_max_accel_std, "m/s^2");
  positive("zupt_velocity_std", zupt_velocity_std, "m/s");
  positive("zupt_pose_std", zupt_pose_std, "m, rad");
  positive("odom_translation_std", odom_translation_std, "m");
  positive("odom_rotation_std", odom_rotation_std, "rad");
  if (!(zupt_max_speed >= 0.0)) err << "zupt_max_speed must be >= 0 m/s (got " << zupt_max_speed << "); ";
  if (!(odom_max_offset >= 0.0)) err << "odom_max_offset must be >= 0 s (got " << odom_max_offset << "); ";
  if (max_states < 2) err << "max_states must be >= 2 (got " << max_states << "); ";
  if (reset_states < 1 || reset_states > max_states)
    err << "reset_states must be in [1, max_states] (got " << reset_states << "); ";
  if (max_iterations < 1) err << "max_iterations must be >= 1 (got " << max_iterations << "); ";
  if (!base_T_imu.matrix().allFinite()) err << "base_T_imu must be finite; ";
  return err.str();
}

SlidingWindow::SlidingWindow(const SlidingWindowConfig& config)
    : config_(config), gravity_(0.0, 0.0, -config.gravity), manifold_(std::make_unique<PoseManifold>()) {
  const std::string err = config_.validate();
  if (!err.empty()) throw std::invalid_argument("fusion config: " + err);
}

SlidingWindow::~SlidingWindow() = default;

void SlidingWindow::setBaseTImu(const Eigen::Isometry3d& base_T_imu) {
  if (!base_T_imu.matrix().allFinite()) throw std::invalid_argument("fusion config: base_T_imu must be finite");
  config_.base_T_imu = base_T_imu;
}

void SlidingWindow::warn(const std::string& message) { warnings_.push_back(message); }

std::vector<std::string> SlidingWindow::takeWarnings() {
  std::vector<std::string> out;
  out.swap(warnings_);
  return out;
}

bool SlidingWindow::addImu(const ImuSample& sample) {
  if (!std::isfinite(sample.stamp) || !sample.gyro.allFinite() || !sample.accel.allFinite()) {
    warn("IMU sample at " + std::to_string(sample.stamp) + " s is not finite: dropped");
    return false;
  }
  if (!imu_.empty() && sample.stamp <= imu_.back().stamp) {
    warn("IMU sample at " + std::to_string(sample.stamp) + " s is not after the previous one (" +
         std::to_string(imu_.back().stamp) + " s): out of order or duplicated, dropped");
    return false;
  }
  if ((sample.gyro_variance < 0.0 || sample.accel_variance < 0.0) && !warned_missing_covariance_) {
    warn("IMU samples carry no covariance: using the configured noise densities");
    warned_missing_covariance_ = true;
  }
  const Eigen::Matrix3d r = config_.base_T_imu.rotation();
  const Eigen::Vector3d lever = config_.base_T_imu.translation();
  BaseSample s;
  s.stamp = sample.stamp;
  s.gyro = r * sample.gyro;
  // The IMU feels the base's acceleration plus the lever arm's tangential and centripetal terms.
  Eigen::Vector3d angular_accel = Eigen::Vector3d::Zero();
  if (!imu_.empty() && sample.stamp - imu_.back().stamp <= config_.max_imu_gap)
    angular_accel = (s.gyro - imu_.back().gyro) / (sample.stamp - imu_.back().stamp);
  s.accel = r * sample.accel - angular_accel.cross(lever) - s.gyro.cross(s.gyro.cross(lever));
  s.gyro_variance = sample.gyro_variance;
  s.accel_variance = sample.accel_variance;
  imu_.push_back(s);
  // Keep what the oldest interval still to be integrated (from the newest state on) and a margin need.
  const double keep_from = states_.empty() ? sample.stamp - 1.0 : states_.back()->stamp - 1.0;
  while (imu_.size() > 2 && imu_[1].stamp < keep_from) imu_.pop_front();
  return true;
}

void SlidingWindow::addOdometry(double stamp, const Eigen::Isometry3d& odom_T_base) {
  if (!std::isfinite(stamp) || !odom_T_base.matrix().allFinite()) return;
  if (!odometry_.empty() && stamp <= odometry_.back().first) return;
  odometry_.emplace_back(stamp, odom_T_base);
  while (odometry_.size() > 2 && odometry_[1].first < stamp - 5.0) odometry_.pop_front();
}

SlidingWindow::Interval SlidingWindow::integrate(double t0, double t1, const State& from) const {
  Interval out{ImuPreintegration(from.bias()), 0.0, false};
  const ImuBias bias = from.bias();
  const Eigen::Matrix3d r0 = from.rotation().toRotationMatrix();
  // The specific force an IMU at rest with attitude r measures: gravity alone, plus the accelerometer bias.
  auto force_at_rest = [&](const Eigen::Matrix3d& r) -> Eigen::Vector3d {
    return r.transpose() * -gravity_ + bias.accel;
  };
  auto next = std::upper_bound(imu_.begin(), imu_.end(), t0, [](double t, const BaseSample& s) { return t < s.stamp; });
  // The sample held at t: the last one at or before it, or the first one if it follows t0 closely.
  const BaseSample* held = next == imu_.begin() ? nullptr : &*(next - 1);
  if (held == nullptr && next != imu_.end() && next->stamp - t0 <= config_.max_imu_gap) held = &*next;
  Eigen::Vector3d last_gyro = held ? held->gyro : bias.gyro;
  const double gyro_var = config_.gyro_noise_density * config_.gyro_noise_density;
  const double accel_var = config_.accel_noise_density * config_.accel_noise_density;
  double t = t0;
  int in_interval = 0;
  Eigen::Vector3d accel_sum = Eigen::Vector3d::Zero(), accel_sq = Eigen::Vector3d::Zero();
  double max_rate = 0.0;
  while (t < t1) {
    const double next_stamp = next == imu_.end() ? std::numeric_limits<double>::infinity() : next->stamp;
    double end = std::min(t1, next_stamp);
    if (held != nullptr && t < held->stamp + config_.max_imu_gap) {
      end = std::min(end, std::max(held->stamp, t0) + config_.max_imu_gap);
      const double dt = end - t;
      if (dt > 0.0) {
        out.pre.integrate(dt, held->gyro, held->accel, held->gyro_variance >= 0.0 ? held->gyro_variance : gyro_var / dt,
                          held->accel_variance >= 0.0 ? held->accel_variance : accel_var / dt);
      }
      last_gyro = held->gyro;
    } else {
      // Dropout: keep turning at the last rate and assume no acceleration in the map frame.
      end = std::min(end, t + kGapStep);
      const double dt = end - t;
      const Eigen::Vector3d accel = force_at_rest(r0 * out.pre.deltaRotation().toRotationMatrix());
      out.pre.integrate(dt, last_gyro, accel, config_.gap_gyro_density * config_.gap_gyro_density / dt,
                        config_.gap_accel_density * config_.gap_accel_density / dt);
      out.gap += dt;
    }
    t = end;
    if (t >= next_stamp) {
      held = &*next;
      ++next;
      ++in_interval;
      accel_sum += held->accel;
      accel_sq += held->accel.cwiseProduct(held->accel);
      max_rate = std::max(max_rate, (held->gyro - bias.gyro).norm());
    }
  }
  if (in_interval >= 2 && out.gap == 0.0) {
    const Eigen::Vector3d mean = accel_sum / in_interval;
    const Eigen::Vector3d var = (accel_sq / in_interval - mean.cwiseProduct(mean)).cwiseMax(0.0);
    // Setting off smoothly keeps the spread small; the mean then departs from what gravity alone gives at rest.
    const Eigen::Vector3d at_rest = force_at_rest(r0);
    out.stationary = max_rate < config_.zupt_max_gyro && var.maxCoeff() < std::pow(config_.zupt_max_accel_std, 2) &&
                     (mean - at_rest).norm() < config_.zupt_max_accel_std &&
                     from.velocity().norm() < config_.zupt_max_speed;
  }
  return out;
}

void SlidingWindow::addFactor(ceres::CostFunction* cost, std::vector<double*> blocks) {
  factors_.push_back(Factor{std::shared_ptr<ceres::CostFunction>(cost), std::move(blocks)});
}

FusedState SlidingWindow::toFused(const State& s) const {
  FusedState f;
  f.stamp = s.stamp;
  f.pose = Eigen::Translation3d(s.pose[0], s.pose[1], s.pose[2]) * s.rotation();
  f.velocity = s.velocity();
  f.bias = s.bias();
  return f;
}

std::optional<FusedState> SlidingWindow::latest() const {
  if (states_.empty()) return std::nullopt;
  return toFused(*states_.back());
}

std::optional<FusedState> SlidingWindow::predict(double stamp) const {
  if (states_.empty()) return std::nullopt;
  const State& s = *states_.back();
  FusedState f = toFused(s);
  if (!(stamp > s.stamp)) return f;
  const Interval in = integrate(s.stamp, stamp, s);
  const double dt = in.pre.duration();
  const Eigen::Matrix3d r = f.pose.rotation();
  f.stamp = stamp;
  f.pose.translation() += f.velocity * dt + 0.5 * gravity_ * dt * dt + r * in.pre.deltaPosition();
  f.pose.linear() = (s.rotation() * in.pre.deltaRotation()).normalized().toRotationMatrix();
  f.velocity += gravity_ * dt + r * in.pre.deltaVelocity();
  return f;
}

std::optional<FusedState> SlidingWindow::addScan(double stamp, const Eigen::Isometry3d* measured,
                                                 const Matrix6d& information) {
  report_ = WindowUpdateReport();
  const bool usable_measurement = measured != nullptr && measured->matrix().allFinite() && information.allFinite();
  if (measured != nullptr && !usable_measurement)
    warn("NDT pose or information at " + std::to_string(stamp) + " s is not finite: ignored");
  if (!std::isfinite(stamp)) {
    warn("scan stamp is not finite: refused");
    return latest();
  }
  if (!states_.empty() && stamp <= states_.back()->stamp) {
    warn("scan at " + std::to_string(stamp) + " s is not after the window's newest state (" +
         std::to_string(states_.back()->stamp) + " s): refused");
    return latest();
  }
  if (states_.empty() && !usable_measurement) return std::nullopt;

  auto state = std::make_unique<State>();
  state->stamp = stamp;
  if (states_.empty()) {
    Eigen::Map<Eigen::Vector3d>(state->pose) = measured->translation();
    Eigen::Map<Eigen::Quaterniond>(state->pose + 3) = Eigen::Quaterniond(measured->rotation()).normalized();
    Eigen::Matrix<double, 9, 1> std;
    std << Eigen::Vector3d::Constant(config_.initial_velocity_std),
        Eigen::Vector3d::Constant(config_.initial_gyro_bias_std),
        Eigen::Vector3d::Constant(config_.initial_accel_bias_std);
    addFactor(SpeedBiasPrior::create(Eigen::Matrix<double, 9, 1>::Zero(), std), {state->speed_bias});
  } else {
    State& prev = *states_.back();
    const Interval in = integrate(prev.stamp, stamp, prev);
    const FusedState guess = *predict(stamp);
    state->position() = guess.pose.translation();
    state->rotation() = Eigen::Quaterniond(guess.pose.rotation());
    std::copy(prev.speed_bias, prev.speed_bias + kSpeedBiasSize, state->speed_bias);
    state->velocity() = guess.velocity;
    addFactor(ImuFactor::create(in.pre, gravity_, config_.gyro_random_walk, config_.accel_random_walk),
              {prev.pose, prev.speed_bias, state->pose, state->speed_bias});
    report_.imu_gap = in.gap;
    if (in.gap > 0.0)
      warn("IMU dropout: " + std::to_string(in.gap) + " s of [" + std::to_string(prev.stamp) + ", " +
           std::to_string(stamp) + "] s without samples, bridged by a constant-velocity model");
    // A steady drive feels like standing still to an IMU: the previous state's velocity tells them apart, so
    // it must have been estimated (a second state), not just the first state's zero-mean prior.
    if (in.stationary && config_.zupt_max_speed > 0.0 && states_.size() >= 2) {
      Eigen::Matrix<double, 9, 1> std;
      std << Eigen::Vector3d::Constant(config_.zupt_velocity_std), Vector6d::Constant(1e6);
      addFactor(SpeedBiasPrior::create(Eigen::Matrix<double, 9, 1>::Zero(), std), {state->speed_bias});
      const Matrix6d still = Matrix6d::Identity() / (config_.zupt_pose_std * config_.zupt_pose_std);
      addFactor(RelativePoseFactor::create(Eigen::Isometry3d::Identity(), still), {prev.pose, state->pose});
      report_.stationary = true;
    }
    // Wheel odometry between the two stamps, when samples lie close enough to both.
    auto nearest = [this](double t) -> const Eigen::Isometry3d* {
      const Eigen::Isometry3d* best = nullptr;
      double best_offset = config_.odom_max_offset;
      for (const auto& [s, pose] : odometry_)
        if (std::abs(s - t) <= best_offset) best_offset = std::abs(s - t), best = &pose;
      return best;
    };
    const Eigen::Isometry3d* odom_i = nearest(prev.stamp);
    const Eigen::Isometry3d* odom_j = nearest(stamp);
    if (odom_i != nullptr && odom_j != nullptr && odom_i != odom_j) {
      Matrix6d info = Matrix6d::Zero();
      info.diagonal() << Eigen::Vector3d::Constant(1.0 / std::pow(config_.odom_translation_std, 2)),
          Eigen::Vector3d::Constant(1.0 / std::pow(config_.odom_rotation_std, 2));
      addFactor(RelativePoseFactor::create(odom_i->inverse() * *odom_j, info), {prev.pose, state->pose});
      report_.odometry = true;
    }
  }
  if (usable_measurement) addFactor(PoseFactor::create(*measured, information), {state->pose});
  states_.push_back(std::move(state));

  solve();
  const auto t0 = std::chrono::steady_clock::now();
  while (states_.size() > static_cast<std::size_t>(config_.max_states)) marginalizeOldest();
  report_.marginalize_ms = msSince(t0);
  return latest();
}

void SlidingWindow::solve() {
  const auto t0 = std::chrono::steady_clock::now();
  ceres::Problem::Options options;
  options.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
#if GPL_CERES_HAS_MANIFOLD
  options.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
#else
  options.local_parameterization_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
#endif
  ceres::Problem problem(options);
  for (auto& s : states_) {
    problem.AddParameterBlock(s->pose, kPoseSize, manifold_.get());
    problem.AddParameterBlock(s->speed_bias, kSpeedBiasSize);
  }
  for (const Factor& f : factors_) problem.AddResidualBlock(f.cost.get(), nullptr, f.blocks);
  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  solver.max_num_iterations = config_.max_iterations;
  // The IMU factors are stiff (information up to 1e10): start Levenberg-Marquardt near Gauss-Newton, or its
  // damping of the weak directions takes ten iterations to relax.
  solver.initial_trust_region_radius = 1e12;
  solver.max_trust_region_radius = 1e16;
  solver.num_threads = 1;
  solver.logging_type = ceres::SILENT;
  ceres::Solver::Summary summary;
  // A failed solve must not leave a NaN behind: keep a copy to restore.
  std::vector<double> backup;
  for (auto& s : states_) {
    backup.insert(backup.end(), s->pose, s->pose + kPoseSize);
    backup.insert(backup.end(), s->speed_bias, s->speed_bias + kSpeedBiasSize);
  }
  ceres::Solve(solver, &problem, &summary);
  bool finite = summary.IsSolutionUsable();
  for (auto& s : states_)
    finite = finite && Eigen::Map<Eigen::Matrix<double, 7, 1>>(s->pose).allFinite() &&
             Eigen::Map<Eigen::Matrix<double, 9, 1>>(s->speed_bias).allFinite();
  if (!finite) {
    warn("window solve failed (" + summary.message + "): kept the previous estimate");
    std::size_t k = 0;
    for (auto& s : states_) {
      std::copy(backup.begin() + k, backup.begin() + k + kPoseSize, s->pose);
      k += kPoseSize;
      std::copy(backup.begin() + k, backup.begin() + k + kSpeedBiasSize, s->speed_bias);
      k += kSpeedBiasSize;
    }
  }
  report_.iterations = static_cast<int>(summary.iterations.size());
  report_.solve_ms = msSince(t0);
}

void SlidingWindow::marginalizeOldest() {
  State& old = *states_.front();
  auto touches_old = [&old](const Factor& f) {
    return std::any_of(f.blocks.begin(), f.blocks.end(),
                       [&old](const double* b) { return b == old.pose || b == old.speed_bias; });
  };
  std::unordered_map<const double*, bool> is_pose;
  for (auto& s : states_) {
    is_pose[s->pose] = true;
    is_pose[s->speed_bias] = false;
  }
  auto tangent = [&is_pose](const double* b) { return is_pose.at(b) ? kPoseTangentSize : kSpeedBiasSize; };

  // Blocks of the removed factors: the old state's first (marginalized), then the ones that stay.
  std::vector<double*> order = {old.pose, old.speed_bias};
  std::vector<Factor> removed, kept_factors;
  for (Factor& f : factors_) {
    if (!touches_old(f)) {
      kept_factors.push_back(std::move(f));
      continue;
    }
    for (double* b : f.blocks)
      if (std::find(order.begin(), order.end(), b) == order.end()) order.push_back(b);
    removed.push_back(std::move(f));
  }
  std::unordered_map<const double*, int> offset;
  int n = 0;
  for (double* b : order) offset[b] = n, n += tangent(b);
  const int m = kPoseTangentSize + kSpeedBiasSize;

  // Gauss-Newton system of the removed factors at the current estimate, in tangent coordinates.
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(n, n);
  Eigen::VectorXd g = Eigen::VectorXd::Zero(n);
  for (const Factor& f : removed) {
    const int rows = f.cost->num_residuals();
    Eigen::VectorXd r(rows);
    std::vector<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> ambient;
    std::vector<double*> jac_ptrs;
    for (std::size_t k = 0; k < f.blocks.size(); ++k) ambient.emplace_back(rows, f.cost->parameter_block_sizes()[k]);
    for (auto& a : ambient) jac_ptrs.push_back(a.data());
    std::vector<const double*> params(f.blocks.begin(), f.blocks.end());
    if (!f.cost->Evaluate(params.data(), r.data(), jac_ptrs.data())) continue;
    std::vector<Eigen::MatrixXd> J;
    for (std::size_t k = 0; k < f.blocks.size(); ++k)
      J.push_back(is_pose.at(f.blocks[k]) ? Eigen::MatrixXd(ambient[k] * posePlusJacobian(f.blocks[k]))
                                          : Eigen::MatrixXd(ambient[k]));
    for (std::size_t a = 0; a < f.blocks.size(); ++a) {
      const int oa = offset.at(f.blocks[a]);
      g.segment(oa, J[a].cols()) += J[a].transpose() * r;
      for (std::size_t b = 0; b < f.blocks.size(); ++b)
        H.block(oa, offset.at(f.blocks[b]), J[a].cols(), J[b].cols()) += J[a].transpose() * J[b];
    }
  }

  factors_ = std::move(kept_factors);
  states_.pop_front();  // `old` is gone from here on
  if (n == m) return;   // nothing else was connected: no prior

  // Schur complement (paper eq. 12-13), with a pseudo-inverse so an unobservable direction cannot blow up.
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig_mm(0.5 *
                                                        (H.topLeftCorner(m, m) + H.topLeftCorner(m, m).transpose()));
  const Eigen::VectorXd lm = eig_mm.eigenvalues();
  const Eigen::VectorXd inv_lm = (lm.array() > 1e-9 * std::max(1.0, lm.maxCoeff())).select(lm.cwiseInverse(), 0.0);
  const Eigen::MatrixXd hmm_inv = eig_mm.eigenvectors() * inv_lm.asDiagonal() * eig_mm.eigenvectors().transpose();
  const Eigen::MatrixXd hrm = H.bottomLeftCorner(n - m, m);
  const Eigen::MatrixXd hs = H.bottomRightCorner(n - m, n - m) - hrm * hmm_inv * hrm.transpose();
  const Eigen::VectorXd gs = g.tail(n - m) - hrm * hmm_inv * g.head(m);

  // hs = J^T J and gs = J^T r for the prior 0.5 |J dx + r|^2.
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(0.5 * (hs + hs.transpose()));
  const Eigen::VectorXd s = eig.eigenvalues();
  const double floor = 1e-9 * std::max(1.0, s.maxCoeff());
  std::vector<int> keep;
  for (int i = 0; i < s.size(); ++i)
    if (s[i] > floor) keep.push_back(i);
  Eigen::MatrixXd jp(keep.size(), n - m);
  Eigen::VectorXd rp(keep.size());
  for (std::size_t i = 0; i < keep.size(); ++i) {
    const Eigen::VectorXd v = eig.eigenvectors().col(keep[i]);
    const double sq = std::sqrt(s[keep[i]]);
    jp.row(i) = sq * v.transpose();
    rp[i] = v.dot(gs) / sq;
  }
  std::vector<PriorBlock> blocks;
  for (std::size_t k = 2; k < order.size(); ++k) {
    PriorBlock b;
    b.data = order[k];
    b.is_pose = is_pose.at(order[k]);
    const int size = b.is_pose ? kPoseSize : kSpeedBiasSize;
    b.linearization_point.assign(order[k], order[k] + size);
    blocks.push_back(std::move(b));
  }
  std::vector<double*> pointers;
  for (const auto& b : blocks) pointers.push_back(b.data);
  if (!keep.empty()) addFactor(new MarginalizationPrior(std::move(blocks), std::move(jp), std::move(rp)), pointers);
}

void SlidingWindow::shrink() {
  while (states_.size() > static_cast<std::size_t>(config_.reset_states)) marginalizeOldest();
}

void SlidingWindow::reset() {
  factors_.clear();
  states_.clear();
  odometry_.clear();
}

}  // namespace grid_puzzle_localization
