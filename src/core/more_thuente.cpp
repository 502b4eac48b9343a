#include "grid_puzzle_localization/more_thuente.hpp"

#include <algorithm>
#include <cmath>

namespace grid_puzzle_localization {
namespace {

// Minimiser of the cubic interpolating (a, fa, ga) and (b, fb, gb) (Nocedal & Wright, eq. 3.59).
double cubicMin(double a, double fa, double ga, double b, double fb, double gb) {
  const double d1 = ga + gb - 3.0 * (fa - fb) / (a - b);
  const double d2 = std::copysign(std::sqrt(std::max(0.0, d1 * d1 - ga * gb)), b - a);
  const double den = gb - ga + 2.0 * d2;
  if (den == 0.0) return 0.5 * (a + b);
  return b - (b - a) * (gb + d2 - d1) / den;
}

// Minimiser of the quadratic through (a, fa) with slope ga and through (b, fb).
double quadMin(double a, double fa, double ga, double b, double fb) {
  const double den = 2.0 * (fb - fa - ga * (b - a));
  if (den == 0.0) return 0.5 * (a + b);
  return a - ga * (b - a) * (b - a) / den;
}

// Zero of the secant of the derivative through (a, ga) and (b, gb).
double secantMin(double a, double ga, double b, double gb) {
  if (gb == ga) return 0.5 * (a + b);
  return a - ga * (b - a) / (gb - ga);
}

struct Interval {
  double al, fl, gl;  // best point so far
  double au, fu, gu;  // other end
  bool bracketed = false;
};

// Trial value selection, the four cases of Section 4 of the paper.
double trialValue(const Interval& I, double at, double ft, double gt, double smin, double smax) {
  if (ft > I.fl) {  // case 1: higher value, the minimiser is bracketed
    const double ac = cubicMin(I.al, I.fl, I.gl, at, ft, gt);
    const double aq = quadMin(I.al, I.fl, I.gl, at, ft);
    return std::abs(ac - I.al) < std::abs(aq - I.al) ? ac : 0.5 * (aq + ac);
  }
  if (gt * I.gl < 0.0) {  // case 2: derivatives of opposite sign
    const double ac = cubicMin(I.al, I.fl, I.gl, at, ft, gt);
    const double as = secantMin(I.al, I.gl, at, gt);
    return std::abs(ac - at) >= std::abs(as - at) ? ac : as;
  }
  if (std::abs(gt) <= std::abs(I.gl)) {  // case 3: same sign, derivative decreases in magnitude
    const double ac = cubicMin(I.al, I.fl, I.gl, at, ft, gt);
    const double as = secantMin(I.al, I.gl, at, gt);
    double next = std::abs(ac - at) < std::abs(as - at) ? ac : as;
    if (!I.bracketed) return std::clamp(next, smin, smax);
    const double limit = at + 0.66 * (I.au - at);
    return at > I.al ? std::min(limit, next) : std::max(limit, next);
  }
  // case 4: same sign, derivative does not decrease
  if (I.bracketed) return cubicMin(at, ft, gt, I.au, I.fu, I.gu);
  return at > I.al ? smax : smin;
}

}  // namespace

double moreThuente(const LineFunction& phi, double phi0, double dphi0, double initial, double step_min, double step_max,
                   const LineSearchParams& params) {
  const double mu = params.mu, nu = params.nu;
  // psi is the auxiliary function of the paper; while it is in use the interval endpoints hold psi values.
  auto psiOf = [&](double a, double f) { return f - phi0 - mu * a * dphi0; };
  bool use_psi = true;
  Interval I{0.0, 0.0, dphi0 - mu * dphi0, 0.0, 0.0, dphi0 - mu * dphi0};
  double at = std::clamp(initial, step_min, step_max);
  double lo = step_min, hi = step_max;  // the current search range
  for (int eval = 1;; ++eval) {
    double f = 0.0, g = 0.0;
    phi(at, &f, &g);
    const double psi = psiOf(at, f), dpsi = g - mu * dphi0;
    if (psi <= 0.0 && std::abs(g) <= nu * std::abs(dphi0)) return at;  // strong Wolfe
    if (eval >= params.max_evaluations) return at;
    if (at >= step_max && psi <= 0.0 && dpsi < 0.0) return at;    // still descending at the longest step
    if (at <= step_min && (psi > 0.0 || dpsi >= 0.0)) return at;  // no progress possible at the shortest step
    if (use_psi && psi <= 0.0 && g >= 0.0) {
      // Switch to phi: convert the stored endpoint values.
      use_psi = false;
      I.fl += phi0 + mu * I.al * dphi0;
      I.gl += mu * dphi0;
      I.fu += phi0 + mu * I.au * dphi0;
      I.gu += mu * dphi0;
    }
    const double ft = use_psi ? psi : f, gt = use_psi ? dpsi : g;
    double next = trialValue(I, at, ft, gt, lo, hi);
    // Interval update rules U1-U3.
    if (ft > I.fl) {
      I.au = at, I.fu = ft, I.gu = gt;
      I.bracketed = true;
    } else if (gt * (I.al - at) > 0.0) {
      I.al = at, I.fl = ft, I.gl = gt;
    } else {
      I.au = I.al, I.fu = I.fl, I.gu = I.gl;
      I.al = at, I.fl = ft, I.gl = gt;
      I.bracketed = true;
    }
    if (I.bracketed) {
      lo = std::max(step_min, std::min(I.al, I.au));
      hi = std::min(step_max, std::max(I.al, I.au));
    }
    if (!std::isfinite(next)) next = 0.5 * (lo + hi);
    next = std::clamp(next, lo, hi);
    if (next == at) return at;  // the interval collapsed onto the current trial
    at = next;
  }
}

}  // namespace grid_puzzle_localization
