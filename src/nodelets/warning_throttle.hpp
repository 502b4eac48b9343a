// Lets each kind of warning through at most once per period. A kind is the warning's text without its
// digits, so "gap of 0.31 s" and "gap of 0.52 s" are one kind and a new kind is never hidden by another.
#pragma once

#include <map>
#include <string>

namespace grid_puzzle_localization {

class WarningThrottle {
 public:
  explicit WarningThrottle(double period) : period_(period) {}

  /// True when `warning` should be logged at time `now` [s]: its kind was not let through within the
  /// last period. A warning let through starts its kind's period again.
  bool pass(const std::string& warning, double now);

 private:
  double period_;                           // [s]
  std::map<std::string, double> last_log_;  // kind -> time it was last let through [s]
};

}  // namespace grid_puzzle_localization
