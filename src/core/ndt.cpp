// NDT score, analytic derivatives and the Newton / More-Thuente loop.
//
// Cost of one source point x against one voxel Gaussian (mean mu, inverse covariance C):
//   f = d1 * e,  e = exp(-d2/2 * d^T C d),  d = R(roll, pitch, yaw) x + t - mu     (d1 < 0, d2 > 0)
// With J = dd/dp = [I | dR_r x, dR_p x, dR_y x] (3x6), q = C d and w = -d1 d2 e:
//   gradient  = J^T (w q)
//   Hessian   = J^T [w (C - d2 q q^T)] J + w q^T d2(R x)/dp_i dp_j
// Summing over a point's neighbours first (b = sum w q, A = sum w (C - d2 q q^T)) and noting that dR and d2R do
// not depend on the point, every pose-dependent factor leaves the sum over points:
//   g_rot_j  = <dR_j, sum b x^T>                       H_rot_ij += <d2R_ij, sum b x^T>
//   H_t_i,rot_j = sum_kl dR_j[k,l] (sum A_ik x_l)      H_rot_ij = sum_klmn dR_i[k,m] dR_j[l,n] (sum A_kl x_m x_n)
// so the per-point work is a few fixed-size outer products, independent of the number of neighbours. dR and d2R
// are the exact derivatives of Rx(roll) Ry(pitch) Rz(yaw) (product rule), checked against finite differences.
#include "grid_puzzle_localization/ndt.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "grid_puzzle_localization/more_thuente.hpp"
#include "omp_threads.hpp"
#include "packed_symmetric.hpp"

namespace grid_puzzle_localization {
namespace {

// The coarse stage (NdtConfig::coarse_points) scores against Gaussians this many times as wide. Its minimum lies a few
// centimetres from the fine one, which the full scan then reaches in one to three iterations.
constexpr double kCoarseWidening = 2.0;
constexpr int kChunk = 256;                   // points per accumulation chunk (fixed: makes the sum thread-count free)
constexpr double kInlierChi2 = 11.345;        // chi2 with 3 dof at 99 %: Mahalanobis^2 bound of an inlier
constexpr std::size_t kMinMatchedVoxels = 3;  // fewer distinct Gaussians cannot pin down 6 DoF reliably
constexpr double kMinHessianEigenRatio = 1e-9;

using packed_symmetric::kCol;
using packed_symmetric::kIndex;
using packed_symmetric::kRow;

struct GaussConstants {
  double d1, d2;
};

// Magnusson (2009), eq. 6.8: fit d1 exp(-d2 x^2 / 2) + d3 to -log(c1 exp(-x^2/2) + c2).
GaussConstants gaussConstants(double resolution, double outlier_ratio) {
  const double c1 = 10.0 * (1.0 - outlier_ratio);
  const double c2 = outlier_ratio / (resolution * resolution * resolution);
  const double d3 = -std::log(c2);
  const double d1 = -std::log(c1 + c2) - d3;
  const double d2 = -2.0 * std::log((-std::log(c1 * std::exp(-0.5) + c2) - d3) / d1);
  return {d1, d2};
}

struct Offsets {
  int n = 0;
  std::array<std::array<int, 3>, 27> d{};
};

Offsets offsetsFor(NdtSearchMethod m) {
  Offsets o;
  o.d[o.n++] = {0, 0, 0};
  if (m == NdtSearchMethod::DIRECT7) {
    for (int a = 0; a < 3; ++a)
      for (int s : {-1, 1}) {
        std::array<int, 3> v{0, 0, 0};
        v[a] = s;
        o.d[o.n++] = v;
      }
  } else if (m == NdtSearchMethod::DIRECT27 || m == NdtSearchMethod::RADIUS) {
    for (int x = -1; x <= 1; ++x)
      for (int y = -1; y <= 1; ++y)
        for (int z = -1; z <= 1; ++z)
          if (x || y || z) o.d[o.n++] = {x, y, z};
  }
  return o;
}

struct Accumulator {
  double cost = 0.0;
  std::size_t matched = 0;     // points with at least one Gaussian in reach
  std::array<double, 3> b{};   // sum b
  std::array<double, 9> B{};   // sum b x^T, row-major
  std::array<double, 6> A{};   // sum A (symmetric)
  std::array<double, 18> T{};  // [sym(i,k)][l]: sum A_ik x_l
  std::array<double, 36> Q{};  // [sym(k,l)][sym(m,n)]: sum A_kl x_m x_n
};

struct RotationDerivatives {
  Eigen::Matrix3d R;
  std::array<Eigen::Matrix3d, 3> d;   // dR / d(roll, pitch, yaw)
  std::array<Eigen::Matrix3d, 6> dd;  // d2R, pairs in sym order (rr rp ry pp py yy)
};

RotationDerivatives rotationDerivatives(double roll, double pitch, double yaw) {
  const double ca = std::cos(roll), sa = std::sin(roll);
  const double cb = std::cos(pitch), sb = std::sin(pitch);
  const double cc = std::cos(yaw), sc = std::sin(yaw);
  std::array<Eigen::Matrix3d, 3> x, y, z;  // [0] value, [1] first derivative, [2] second derivative
  x[0] << 1, 0, 0, 0, ca, -sa, 0, sa, ca;
  x[1] << 0, 0, 0, 0, -sa, -ca, 0, ca, -sa;
  x[2] << 0, 0, 0, 0, -ca, sa, 0, -sa, -ca;
  y[0] << cb, 0, sb, 0, 1, 0, -sb, 0, cb;
  y[1] << -sb, 0, cb, 0, 0, 0, -cb, 0, -sb;
  y[2] << -cb, 0, -sb, 0, 0, 0, sb, 0, -cb;
  z[0] << cc, -sc, 0, sc, cc, 0, 0, 0, 1;
  z[1] << -sc, -cc, 0, cc, -sc, 0, 0, 0, 0;
  z[2] << -cc, sc, 0, -sc, -cc, 0, 0, 0, 0;
  RotationDerivatives r;
  r.R = x[0] * y[0] * z[0];
  // Derivative orders of (roll, pitch, yaw) for each term.
  auto term = [&](int i, int j, int k) { return Eigen::Matrix3d(x[i] * y[j] * z[k]); };
  r.d = {term(1, 0, 0), term(0, 1, 0), term(0, 0, 1)};
  r.dd = {term(2, 0, 0), term(1, 1, 0), term(1, 0, 1), term(0, 2, 0), term(0, 1, 1), term(0, 0, 2)};
  return r;
}

struct FinalStats {
  double nvtl = 0.0;
  double inlier_fraction = 0.0;
  std::size_t matched_voxels = 0;  // distinct Gaussians matched, counted up to kMinMatchedVoxels
};

// Collects distinct Gaussians up to kMinMatchedVoxels: enough to tell a degenerate match, at no sorting cost.
void addDistinct(std::vector<const VoxelGaussian*>& set, const VoxelGaussian* g) {
  if (set.size() >= kMinMatchedVoxels || std::find(set.begin(), set.end(), g) != set.end()) return;
  set.push_back(g);
}

class Evaluator {
 public:
  /// `widening` >= 1 scales every Gaussian's standard deviation (d2 / widening^2): a smoother cost with a wider basin.
  Evaluator(const VoxelMap& map, const PointCloud& points, const NdtConfig& cfg, double widening = 1.0)
      : map_(map),
        points_(points),
        offsets_(offsetsFor(cfg.search)),
        radius_(cfg.search == NdtSearchMethod::RADIUS),
        r2_(static_cast<float>(map.resolution() * map.resolution())),
        inv_res_(static_cast<float>(1.0 / map.resolution())),
        threads_(resolveThreads(cfg.threads)) {
    const GaussConstants g = gaussConstants(map.resolution(), cfg.outlier_ratio);
    d1_ = static_cast<float>(g.d1);
    d2_ = static_cast<float>(g.d2 / (widening * widening));
    chunks_.resize((points.size() + kChunk - 1) / kChunk);
  }

  std::size_t lastMatched() const { return matched_; }

  NdtDerivatives evaluate(const Vector6d& p, bool hessian) {
    const RotationDerivatives rd = rotationDerivatives(p(3), p(4), p(5));
    const Eigen::Matrix3f R = rd.R.cast<float>();
    const Eigen::Vector3f t = p.head<3>().cast<float>();
    const int n_chunks = static_cast<int>(chunks_.size());
#pragma omp parallel for num_threads(threads_) schedule(dynamic, 1)
    for (int c = 0; c < n_chunks; ++c) {
      const std::size_t lo = static_cast<std::size_t>(c) * kChunk;
      const std::size_t hi = std::min(points_.size(), lo + kChunk);
      chunks_[c] = hessian ? accumulate<true>(R, t, lo, hi) : accumulate<false>(R, t, lo, hi);
    }
    Accumulator s;  // reduced in chunk order: deterministic whatever the thread count
    for (const Accumulator& a : chunks_) {
      s.cost += a.cost;
      s.matched += a.matched;
      for (int i = 0; i < 3; ++i) s.b[i] += a.b[i];
      for (int i = 0; i < 9; ++i) s.B[i] += a.B[i];
      for (int i = 0; i < 6; ++i) s.A[i] += a.A[i];
      for (int i = 0; i < 18; ++i) s.T[i] += a.T[i];
      for (int i = 0; i < 36; ++i) s.Q[i] += a.Q[i];
    }
    matched_ = s.matched;
    return assemble(s, rd, hessian);
  }

  FinalStats finalStats(const Vector6d& p) {
    const Eigen::Matrix3f R = rotationDerivatives(p(3), p(4), p(5)).R.cast<float>();
    const Eigen::Vector3f t = p.head<3>().cast<float>();
    const int n_chunks = static_cast<int>(chunks_.size());
    std::vector<double> best_sum(n_chunks, 0.0);
    std::vector<std::size_t> matched(n_chunks, 0), inliers(n_chunks, 0);
    std::vector<std::vector<const VoxelGaussian*>> used(n_chunks);
#pragma omp parallel for num_threads(threads_) schedule(dynamic, 1)
    for (int c = 0; c < n_chunks; ++c) {
      const std::size_t lo = static_cast<std::size_t>(c) * kChunk;
      const std::size_t hi = std::min(points_.size(), lo + kChunk);
      for (std::size_t i = lo; i < hi; ++i) {
        float best = -1.0f, best_m = std::numeric_limits<float>::infinity();
        forNeighbours(R * points_[i] + t, [&](const VoxelGaussian& g, const Eigen::Vector3f& d) {
          const float m = mahalanobis(g, d);
          best = std::max(best, -d1_ * std::exp(-0.5f * d2_ * m));
          best_m = std::min(best_m, m);
          addDistinct(used[c], &g);
        });
        if (best < 0.0f) continue;
        ++matched[c];
        best_sum[c] += best;
        inliers[c] += best_m <= kInlierChi2;
      }
    }
    FinalStats f;
    std::size_t m = 0, in = 0;
    double sum = 0.0;
    std::vector<const VoxelGaussian*> all;
    for (int c = 0; c < n_chunks; ++c) {
      m += matched[c];
      in += inliers[c];
      sum += best_sum[c];
      for (const VoxelGaussian* g : used[c]) addDistinct(all, g);
    }
    f.matched_voxels = all.size();
    f.nvtl = m ? sum / static_cast<double>(m) : 0.0;
    f.inlier_fraction = points_.empty() ? 0.0 : static_cast<double>(in) / static_cast<double>(points_.size());
    return f;
  }

 private:
  static float mahalanobis(const VoxelGaussian& g, const Eigen::Vector3f& d) {
    const auto& c = g.inv_cov;
    return d.x() * (c[0] * d.x() + 2.0f * (c[1] * d.y() + c[2] * d.z())) +
           d.y() * (c[3] * d.y() + 2.0f * c[4] * d.z()) + c[5] * d.z() * d.z();
  }

  template <class F>
  void forNeighbours(const Eigen::Vector3f& y, F&& f) const {
    const std::int32_t kx = static_cast<std::int32_t>(std::floor(y.x() * inv_res_));
    const std::int32_t ky = static_cast<std::int32_t>(std::floor(y.y() * inv_res_));
    const std::int32_t kz = static_cast<std::int32_t>(std::floor(y.z() * inv_res_));
    for (int o = 0; o < offsets_.n; ++o) {
      const auto& off = offsets_.d[o];
      const VoxelGaussian* g = map_.find({kx + off[0], ky + off[1], kz + off[2]});
      if (!g) continue;
      const Eigen::Vector3f d = y - g->mean;
      if (radius_ && !(d.squaredNorm() < r2_)) continue;
      f(*g, d);
    }
  }

  template <bool kHessian>
  Accumulator accumulate(const Eigen::Matrix3f& R, const Eigen::Vector3f& t, std::size_t lo, std::size_t hi) const {
    Accumulator acc;
    float fb[3] = {}, fB[9] = {}, fA[6] = {}, fT[18] = {}, fQ[36] = {};
    const float d1 = d1_, d2 = d2_;
    for (std::size_t i = lo; i < hi; ++i) {
      const Eigen::Vector3f& x = points_[i];
      float b[3] = {0, 0, 0};
      float A[6] = {0, 0, 0, 0, 0, 0};
      bool any = false;
      double cost = 0.0;
      forNeighbours(R * x + t, [&](const VoxelGaussian& g, const Eigen::Vector3f& d) {
        const auto& c = g.inv_cov;
        const float q0 = c[0] * d.x() + c[1] * d.y() + c[2] * d.z();
        const float q1 = c[1] * d.x() + c[3] * d.y() + c[4] * d.z();
        const float q2 = c[2] * d.x() + c[4] * d.y() + c[5] * d.z();
        const float m = d.x() * q0 + d.y() * q1 + d.z() * q2;
        const float e = std::exp(-0.5f * d2 * m);
        cost += d1 * e;
        const float w = -d1 * d2 * e;
        b[0] += w * q0;
        b[1] += w * q1;
        b[2] += w * q2;
        if (kHessian) {
          const float wd2 = w * d2;
          A[0] += w * c[0] - wd2 * q0 * q0;
          A[1] += w * c[1] - wd2 * q0 * q1;
          A[2] += w * c[2] - wd2 * q0 * q2;
          A[3] += w * c[3] - wd2 * q1 * q1;
          A[4] += w * c[4] - wd2 * q1 * q2;
          A[5] += w * c[5] - wd2 * q2 * q2;
        }
        any = true;
      });
      if (!any) continue;
      ++acc.matched;
      acc.cost += cost;
      const float xd[3] = {x.x(), x.y(), x.z()};
      for (int k = 0; k < 3; ++k) {
        fb[k] += b[k];
        for (int l = 0; l < 3; ++l) fB[3 * k + l] += b[k] * xd[l];
      }
      if (kHessian) {
        const float xx[6] = {xd[0] * xd[0], xd[0] * xd[1], xd[0] * xd[2], xd[1] * xd[1], xd[1] * xd[2], xd[2] * xd[2]};
        for (int s = 0; s < 6; ++s) {
          const float a = A[s];
          fA[s] += a;
          for (int l = 0; l < 3; ++l) fT[3 * s + l] += a * xd[l];
          for (int u = 0; u < 6; ++u) fQ[6 * s + u] += a * xx[u];
        }
      }
    }
    // Float sums over one chunk (<= kChunk points) lose ~1e-5 relative at worst; chunks are summed in double.
    for (int k = 0; k < 3; ++k) acc.b[k] = fb[k];
    for (int k = 0; k < 9; ++k) acc.B[k] = fB[k];
    for (int k = 0; k < 6; ++k) acc.A[k] = fA[k];
    for (int k = 0; k < 18; ++k) acc.T[k] = fT[k];
    for (int k = 0; k < 36; ++k) acc.Q[k] = fQ[k];
    return acc;
  }

  static NdtDerivatives assemble(const Accumulator& s, const RotationDerivatives& rd, bool hessian) {
    NdtDerivatives out;
    out.cost = s.cost;
    const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> B(s.B.data());
    for (int i = 0; i < 3; ++i) out.gradient(i) = s.b[i];
    for (int j = 0; j < 3; ++j) out.gradient(3 + j) = (rd.d[j].array() * B.array()).sum();
    if (!hessian) return out;
    Matrix6d& H = out.hessian;
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k) H(i, k) = s.A[kIndex[i][k]];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        double v = 0.0;
        for (int k = 0; k < 3; ++k)
          for (int l = 0; l < 3; ++l) v += rd.d[j](k, l) * s.T[3 * kIndex[i][k] + l];
        H(i, 3 + j) = H(3 + j, i) = v;
      }
    for (int u = 0; u < 6; ++u) {
      const int i = kRow[u], j = kCol[u];
      double v = (rd.dd[u].array() * B.array()).sum();
      for (int k = 0; k < 3; ++k)
        for (int l = 0; l < 3; ++l)
          for (int m = 0; m < 3; ++m)
            for (int n = 0; n < 3; ++n) v += rd.d[i](k, m) * rd.d[j](l, n) * s.Q[6 * kIndex[k][l] + kIndex[m][n]];
      H(3 + i, 3 + j) = H(3 + j, 3 + i) = v;
    }
    return out;
  }

  const VoxelMap& map_;
  const PointCloud& points_;
  Offsets offsets_;
  bool radius_;
  float r2_, inv_res_;
  int threads_;
  float d1_ = 0.0f, d2_ = 0.0f;
  std::vector<Accumulator> chunks_;
  std::size_t matched_ = 0;
};

PointCloud finitePoints(const PointCloud& source) {
  PointCloud pts;
  pts.reserve(source.size());
  for (const Point& p : source)
    if (p.allFinite()) pts.push_back(p);
  return pts;
}

// Newton step -H^-1 g. Where H is not positive definite (a saddle or a concave region, common far from the
// optimum with DIRECT searches) its eigenvalues are replaced by their magnitudes (saddle-free Newton), so the step
// is always a descent direction instead of stalling; at a proper minimum this is the plain Newton step.
Vector6d newtonStep(const NdtDerivatives& D) {
  Eigen::SelfAdjointEigenSolver<Matrix6d> eig(D.hessian);
  const Vector6d& l = eig.eigenvalues();
  const double floor = 1e-6 * std::max(1.0, l.cwiseAbs().maxCoeff());
  const Vector6d inv = l.cwiseAbs().cwiseMax(floor).cwiseInverse();
  return -(eig.eigenvectors() * inv.asDiagonal() * eig.eigenvectors().transpose()) * D.gradient;
}

bool isPositiveDefinite(const Matrix6d& H) { return Eigen::LLT<Matrix6d>(H).info() == Eigen::Success; }

NdtResult failure(NdtResult r, NdtResultStatus status, const std::string& message) {
  r.status = status;
  r.message = message;
  r.converged = false;
  return r;
}

struct DescentResult {
  int iterations = 0;
  bool converged = false;
};

// Newton iterations with the line search from *p, where *D holds the derivatives, until the step falls below
// transformation_epsilon at a positive definite Hessian or max_iterations; *p and *D end at the last iterate. Counts
// each pass over the source in *evaluations.
DescentResult descend(Evaluator& ev, const NdtConfig& config, Vector6d* p, NdtDerivatives* D, int* evaluations) {
  const double epsilon = config.transformation_epsilon;
  auto evaluate = [&](const Vector6d& pose) {
    ++*evaluations;
    return ev.evaluate(pose, true);
  };
  DescentResult out;
  double step_limit = config.step_size;
  for (out.iterations = 0; out.iterations < config.max_iterations;) {
    const Vector6d delta = newtonStep(*D);
    const double norm = delta.norm();
    if (!std::isfinite(norm)) break;
    if (norm == 0.0) {
      out.converged = true;
      break;
    }
    Vector6d dir = delta / norm;
    double slope = D->gradient.dot(dir);
    if (slope > 0.0) {  // the Hessian is not positive definite here: go downhill along the flipped direction
      dir = -dir;
      slope = -slope;
    }
    ++out.iterations;
    if (slope == 0.0) {
      out.converged = true;
      break;
    }
    // At a positive definite Hessian a Newton step shorter than transformation_epsilon lands on the minimum of the
    // local quadratic model, and the cost decrease it brings (second order in the step) is below the round-off of
    // the float sums and the jumps where points change voxels. A line search cannot measure it: it kept shrinking
    // such a step for up to max_evaluations passes over the scan and then took almost none of it. Take it whole.
    const bool newton_converged = norm < epsilon && isPositiveDefinite(D->hessian);
    double step = 0.0;
    if (config.line_search && !newton_converged) {
      NdtDerivatives trial;
      step = moreThuente(
          [&](double a, double* value, double* deriv) {
            trial = evaluate(*p + a * dir);
            *value = trial.cost;
            *deriv = trial.gradient.dot(dir);
          },
          D->cost, slope, norm, 0.0, step_limit);
      *D = trial;
    } else {
      step = std::min(norm, step_limit);
      *D = evaluate(*p + step * dir);
    }
    *p += step * dir;
    // A line-searched step that reached the limit and still went downhill says the local model holds further out:
    // allow twice as long a step next time (without a line search nothing checks a longer step, so it stays fixed).
    // A shorter step found its minimum along the direction: back to the configured limit, so the last iterations
    // near the optimum are as fine as ever.
    const bool downhill_at_limit = config.line_search && step >= step_limit && D->gradient.dot(dir) < 0.0;
    step_limit = downhill_at_limit ? std::min(2.0 * step_limit, config.max_step_size) : config.step_size;
    // A short step alone is not convergence: DIRECT searches can stall on a saddle or a ridge of the piecewise-
    // smooth cost, where the saddle-free step keeps going downhill. Require a positive definite Hessian too.
    if (newton_converged || (step < epsilon && isPositiveDefinite(D->hessian))) {
      out.converged = true;
      break;
    }
  }
  return out;
}

}  // namespace

NdtAligner::NdtAligner(const NdtConfig& config) : config_(config) {
  const std::string problem = config.validate();
  if (!problem.empty()) throw std::invalid_argument("NdtAligner: " + problem);
}

NdtDerivatives NdtAligner::derivatives(const VoxelMap& target, const PointCloud& source, const Vector6d& pose) const {
  const PointCloud pts = finitePoints(source);
  Evaluator ev(target, pts, config_);
  return ev.evaluate(pose, true);
}

bool NdtAligner::hasCoarseStage(std::size_t points) const {
  return config_.coarse_points > 0 && points >= 2 * static_cast<std::size_t>(config_.coarse_points);
}

Vector6d NdtAligner::coarseStage(const VoxelMap& target, const PointCloud& points, const Vector6d& guess,
                                 int* evaluations, bool from_coarse_map) const {
  const std::size_t n = points.size();
  if (!hasCoarseStage(n)) return guess;
  const std::size_t stride = n / static_cast<std::size_t>(config_.coarse_points);
  PointCloud sample;
  sample.reserve(n / stride + 1);
  for (std::size_t i = 0; i < n; i += stride) sample.push_back(points[i]);
  Vector6d start = guess;
  const VoxelMap* coarse = from_coarse_map ? target.coarse() : nullptr;
  if (coarse) {
    // Voxels coarse_map_factor times as large reach as much farther; the step limits grow with them.
    Evaluator ec(*coarse, sample, config_);
    NdtDerivatives Dc = ec.evaluate(start, true);
    ++*evaluations;
    if (ec.lastMatched() > 0) {
      NdtConfig wide = config_;
      wide.step_size *= coarse->resolution() / config_.resolution;
      wide.max_step_size *= coarse->resolution() / config_.resolution;
      Vector6d p = start;
      descend(ec, wide, &p, &Dc, evaluations);
      if (p.allFinite()) start = p;
    }
  }
  Evaluator ev(target, sample, config_, kCoarseWidening);
  Vector6d p = start;
  NdtDerivatives D = ev.evaluate(p, true);
  ++*evaluations;
  if (ev.lastMatched() == 0) return start;
  // NdtConfig::coarse_yaw_probe: also the start turned either way; the descent starts from the best of the three.
  for (const double yaw : {config_.coarse_yaw_probe, -config_.coarse_yaw_probe}) {
    if (yaw == 0.0) break;
    Vector6d turned = start;
    turned(5) += yaw;
    const NdtDerivatives Dt = ev.evaluate(turned, true);
    ++*evaluations;
    if (ev.lastMatched() > 0 && Dt.cost < D.cost) {
      p = turned;
      D = Dt;
    }
  }
  descend(ev, config_, &p, &D, evaluations);
  return p.allFinite() ? p : start;
}

std::optional<Eigen::Isometry3d> NdtAligner::coarseAlign(const VoxelMap& target, const PointCloud& source,
                                                         const Eigen::Isometry3d& guess, bool from_coarse_map) const {
  const PointCloud pts = finitePoints(source);
  if (!hasCoarseStage(pts.size()) || target.resolution() != config_.resolution || target.gaussianCount() == 0 ||
      !guess.matrix().allFinite())
    return std::nullopt;
  int evaluations = 0;
  return Eigen::Isometry3d(
      poseToMatrix(coarseStage(target, pts, matrixToPose(guess.matrix()), &evaluations, from_coarse_map)));
}

NdtResult NdtAligner::align(const VoxelMap& target, const PointCloud& source, const Eigen::Matrix4f& guess,
                            bool from_coarse_map) const {
  NdtResult r;
  const PointCloud pts = finitePoints(source);
  r.source_points = pts.size();
  if (!guess.allFinite()) return failure(r, NdtResultStatus::INVALID_INPUT, "the initial guess has non-finite entries");
  r.transform = guess;
  if (target.resolution() != config_.resolution) {
    std::ostringstream msg;
    msg << "the target was built with resolution " << target.resolution() << " m but the aligner uses "
        << config_.resolution << " m; build the NdtTarget from the same NdtConfig";
    return failure(r, NdtResultStatus::INVALID_INPUT, msg.str());
  }
  if (target.gaussianCount() == 0)
    return failure(r, NdtResultStatus::EMPTY_TARGET,
                   "the target has no voxel with at least " + std::to_string(target.params().min_points_per_voxel) +
                       " points; load map points around the pose first");
  if (pts.size() < kMinSourcePoints)
    return failure(r, NdtResultStatus::TOO_FEW_POINTS,
                   "the source has " + std::to_string(pts.size()) + " finite points, at least " +
                       std::to_string(kMinSourcePoints) + " are needed");

  Evaluator ev(target, pts, config_);
  Vector6d p = matrixToPose(guess.cast<double>());
  NdtDerivatives D = ev.evaluate(p, true);
  ++r.evaluations;
  if (ev.lastMatched() == 0)
    return failure(r, NdtResultStatus::NO_CORRESPONDENCE,
                   "no source point lies near a target voxel at the initial guess; check the guess and the map");
  // A guess whose Newton step fits within step_size at a positive definite Hessian is in the minimum's basin already
  // (the common tracking case): the full scan converges from it in a pass or two, and a coarse stage would only add
  // to that. A guess farther off goes through the coarse stage, whose answer is kept when the full scan scores it
  // better than the guess.
  const bool near_minimum = newtonStep(D).norm() <= config_.step_size && isPositiveDefinite(D.hessian);
  if (!near_minimum) {
    const Vector6d coarse = coarseStage(target, pts, p, &r.coarse_evaluations, from_coarse_map);
    if (coarse != p) {
      const NdtDerivatives Dc = ev.evaluate(coarse, true);
      ++r.evaluations;
      if (ev.lastMatched() > 0 && Dc.cost < D.cost) {
        p = coarse;
        D = Dc;
      }
    }
  }

  const DescentResult fine = descend(ev, config_, &p, &D, &r.evaluations);
  r.iterations = fine.iterations;
  const bool converged = fine.converged;
  if (!p.allFinite() || !D.hessian.allFinite())
    return failure(r, NdtResultStatus::DEGENERATE,
                   "the optimisation diverged to a non-finite pose; the guess is returned");

  const FinalStats fs = ev.finalStats(p);
  const Vector6d magnitudes = Eigen::SelfAdjointEigenSolver<Matrix6d>(D.hessian).eigenvalues().cwiseAbs();
  r.hessian = D.hessian;
  r.score = D.cost;
  r.transformation_probability = -D.cost / static_cast<double>(pts.size());
  r.nvtl = fs.nvtl;
  r.inlier_fraction = fs.inlier_fraction;
  if (fs.matched_voxels < kMinMatchedVoxels)
    return failure(r, NdtResultStatus::DEGENERATE,
                   "the match is degenerate: only " + std::to_string(fs.matched_voxels) +
                       " distinct target voxels matched (at least " + std::to_string(kMinMatchedVoxels) +
                       " are needed to fix 6 DoF); the guess is returned");
  if (!(magnitudes.minCoeff() > kMinHessianEigenRatio * magnitudes.maxCoeff())) {
    std::ostringstream msg;
    msg << "the match is degenerate: the Hessian is singular (eigenvalue magnitudes in [" << magnitudes.minCoeff()
        << ", " << magnitudes.maxCoeff() << "]), some direction is unconstrained; the guess is returned";
    return failure(r, NdtResultStatus::DEGENERATE, msg.str());
  }
  r.transform = poseToMatrix(p).cast<float>();
  r.converged = converged;
  r.status = converged ? NdtResultStatus::OK : NdtResultStatus::MAX_ITERATIONS;
  if (!converged)
    r.message = "stopped after max_iterations before the step fell below transformation_epsilon at a minimum";
  return r;
}

}  // namespace grid_puzzle_localization
