// More-Thuente line search (More & Thuente 1994, "Line search algorithms with guaranteed sufficient decrease").
#pragma once

#include <functional>

namespace grid_puzzle_localization {

struct LineSearchParams {
  double mu = 1e-4;          ///< sufficient decrease constant, (0, 1)
  double nu = 0.9;           ///< curvature constant, (mu, 1)
  int max_evaluations = 10;  ///< function evaluations, >= 1
};

/// Evaluates phi(alpha) and phi'(alpha) along a search direction.
using LineFunction = std::function<void(double alpha, double* value, double* derivative)>;

/// Finds a step in [step_min, step_max] satisfying the strong Wolfe conditions for phi, starting at `initial`.
/// phi0 = phi(0), dphi0 = phi'(0) < 0 (a descent direction). The returned step is always the last one `phi` was
/// evaluated at, so a caller caching per-evaluation data (gradients, Hessians) holds the data of the result.
double moreThuente(const LineFunction& phi, double phi0, double dphi0, double initial, double step_min, double step_max,
                   const LineSearchParams& params = LineSearchParams());

}  // namespace grid_puzzle_localization
