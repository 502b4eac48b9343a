// Point-to-distribution NDT registration (Magnusson 2009) with OpenMP. No ROS includes here.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <optional>
#include <string>

#include "grid_puzzle_localization/matrix6.hpp"
#include "grid_puzzle_localization/point_cloud.hpp"
#include "grid_puzzle_localization/voxel_map.hpp"

namespace grid_puzzle_localization {

/// Which target voxels a transformed source point is scored against.
enum class NdtSearchMethod {
  DIRECT1,   ///< the voxel holding the point
  DIRECT7,   ///< plus its 6 face neighbours
  DIRECT27,  ///< the full 3x3x3 block
  RADIUS,    ///< every voxel whose mean lies within `resolution` of the point (PCL's behaviour)
};

/// Parses "DIRECT1" | "DIRECT7" | "DIRECT27" | "RADIUS" (case-insensitive); false if unknown.
bool parseSearchMethod(const std::string& text, NdtSearchMethod* method);
const char* toString(NdtSearchMethod method);

/// Every NDT parameter. The target-side ones (resolution, min_points_per_voxel, eigenvalue_ratio, threads) come
/// from VoxelMapParams, so an NdtConfig can be passed to NdtTarget as is.
struct NdtConfig : VoxelMapParams {
  NdtSearchMethod search = NdtSearchMethod::DIRECT7;
  double step_size = 0.1;  ///< maximum Newton step length (norm of the 6-vector, m and rad), > 0
  /// >= step_size; while the line search ends at the step limit still going downhill, the limit doubles for the
  /// next iteration, up to this (a trust region that grows where the local model holds); it falls back to
  /// step_size after a step that stops short of the limit. Equal to step_size: PCL's fixed limit.
  double max_step_size = 0.8;
  double transformation_epsilon = 0.01;  ///< converged when the step length falls below this, >= 0
  int max_iterations = 30;               ///< Newton iterations, >= 1
  double outlier_ratio = 0.55;           ///< weight of the uniform outlier term of the mixture, (0, 1)
  bool line_search = true;               ///< More-Thuente line search; false = fixed step min(|newton|, step_size)
  /// >= 0, 0 = one stage; when the guess is not yet near a minimum (its Newton step is longer than step_size or the
  /// Hessian is not positive definite), a source of at least twice this many points is first aligned as an even
  /// subsample of about this many points: on the target's coarse map first when align() is asked to
  /// (coarse_map_factor), then against Gaussians twice as wide (a smoother cost with a wider basin), then in full from
  /// there when the full scan scores that better than the guess. A guess far off costs passes over the subsample
  /// instead of the scan.
  int coarse_points = 1500;
  /// [rad] in [0, pi); the coarse stage starts from the best (by its cost) of the guess and the guess turned this far
  /// either way about its z axis. A vehicle entering a turn between keyframes is predicted 0.15-0.25 rad off in yaw,
  /// and from there the coarse cost descends into a false basin that keeps the old heading. 0 = from the guess only.
  double coarse_yaw_probe = 0.1;

  /// Empty when usable, else a message naming each bad value and its allowed range (includes the map params).
  std::string validate() const;
};

enum class NdtResultStatus {
  OK,                 ///< converged (step below transformation_epsilon)
  MAX_ITERATIONS,     ///< stopped at max_iterations; the pose is the last iterate and usually still usable
  EMPTY_TARGET,       ///< the target snapshot has no valid Gaussian
  TOO_FEW_POINTS,     ///< the source has fewer than kMinSourcePoints finite points
  NO_CORRESPONDENCE,  ///< no source point reached a target Gaussian at the guess
  DEGENERATE,         ///< the match does not constrain all 6 DoF (e.g. one voxel); the pose is the guess
  INVALID_INPUT,      ///< non-finite guess, bad config, or a snapshot built with another resolution
};
const char* toString(NdtResultStatus status);

/// The rigid transform of an NDT result's `transform`, its rotation made orthonormal again (float round-off leaves it
/// slightly off) so that it can be chained with other poses.
Eigen::Isometry3d toIsometry(const Eigen::Matrix4f& m);

/// Result of one alignment. All fields are finite whatever the status.
struct NdtResult {
  Eigen::Matrix4f transform = Eigen::Matrix4f::Identity();  ///< T_target_source: maps source points into the target
  int iterations = 0;                                       ///< Newton iterations done
  /// Passes over the source computing cost, gradient and Hessian (the initial one and every line-search trial).
  int evaluations = 0;
  int coarse_evaluations = 0;  ///< passes over the coarse stage's subsample (NdtConfig::coarse_points), 0 without one
  bool converged = false;      ///< status == OK
  /// NDT cost: sum over source points and their Gaussians of d1 * exp(-d2/2 * mahalanobis^2), <= 0, lower is better.
  double score = 0.0;
  double transformation_probability = 0.0;  ///< -score / source points (Autoware's "transformation probability")
  double nvtl = 0.0;  ///< nearest voxel transformation likelihood: mean over matched points of the best -d1*exp(..)
  /// Hessian of the cost w.r.t. (x, y, z, roll, pitch, yaw) at the final pose, with the pose parametrised as
  /// T = Translation(x, y, z) * Rx(roll) * Ry(pitch) * Rz(yaw). Positive definite at a well-constrained minimum;
  /// its inverse is a covariance estimate (up to scale) in [m, rad].
  Matrix6d hessian = Matrix6d::Zero();
  double inlier_fraction = 0.0;   ///< source points whose best Gaussian is within chi2(3 dof, 99%) Mahalanobis
  std::size_t source_points = 0;  ///< finite source points used
  NdtResultStatus status = NdtResultStatus::INVALID_INPUT;
  std::string message;  ///< empty when OK, else what went wrong and what to do
};

/// Pose parameters (x, y, z [m], roll, pitch, yaw [rad]) <-> T = Translation * Rx(roll) * Ry(pitch) * Rz(yaw).
Eigen::Matrix4d poseToMatrix(const Vector6d& pose);
Vector6d matrixToPose(const Eigen::Matrix4d& transform);

/// The NDT cost at a pose and its analytic derivatives w.r.t. the pose parameters.
struct NdtDerivatives {
  double cost = 0.0;
  Vector6d gradient = Vector6d::Zero();
  Matrix6d hessian = Matrix6d::Zero();
};

/// Aligns source clouds against a target snapshot. Stateless apart from its config: align() is const and may
/// run concurrently from several threads (each call uses its own OpenMP team).
class NdtAligner {
 public:
  static constexpr std::size_t kMinSourcePoints = 6;

  /// Throws std::invalid_argument when config.validate() is not empty.
  explicit NdtAligner(const NdtConfig& config = NdtConfig());
  const NdtConfig& config() const { return config_; }

  /// Aligns `source` (sensor frame, metres) to `target` starting at `guess` (T_target_source). The target must have
  /// been built with this config's resolution. With `from_coarse_map`, the coarse stage of a guess that is not near a
  /// minimum starts on target.coarse() (when the target has one): for a guess that may be metres off. Never throws
  /// for bad data: see NdtResult::status.
  NdtResult align(const VoxelMap& target, const PointCloud& source, const Eigen::Matrix4f& guess,
                  bool from_coarse_map = false) const;
  NdtResult align(const VoxelMap& target, const PointCloud& source, const Eigen::Isometry3f& guess,
                  bool from_coarse_map = false) const {
    return align(target, source, guess.matrix(), from_coarse_map);
  }

  /// The cost, gradient and Hessian that align() minimises, at `pose` (finite source points only). For tests and
  /// for a covariance at a pose found elsewhere.
  NdtDerivatives derivatives(const VoxelMap& target, const PointCloud& source, const Vector6d& pose) const;

  /// Where the coarse stage alone leads from `guess` (T_target_source): passes over the subsample against the wider
  /// Gaussians, none over the whole source; with `from_coarse_map`, first against target.coarse() as in align().
  /// Empty when this source has no coarse stage (coarse_points = 0, fewer than twice as many finite points, an empty
  /// target or one of another resolution).
  std::optional<Eigen::Isometry3d> coarseAlign(const VoxelMap& target, const PointCloud& source,
                                               const Eigen::Isometry3d& guess, bool from_coarse_map = false) const;

 private:
  /// A source of `points` finite points gets a coarse stage (NdtConfig::coarse_points).
  bool hasCoarseStage(std::size_t points) const;
  /// The pose the coarse stage reaches from `guess` (NdtConfig::coarse_points), `guess` itself without one. With
  /// `from_coarse_map`, the subsample first descends against target.coarse() when there is one.
  Vector6d coarseStage(const VoxelMap& target, const PointCloud& points, const Vector6d& guess, int* evaluations,
                       bool from_coarse_map) const;

  NdtConfig config_;
};

}  // namespace grid_puzzle_localization
