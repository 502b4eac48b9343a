// When to start a global search by itself: once no initial pose has come for a timeout after the first scan
// that waited for one, and again a timeout after each search that found nothing.
#pragma once

#include <optional>

namespace grid_puzzle_localization {

class GlobalSearchTimer {
 public:
  /// `timeout` [s], <= 0: never start a search.
  explicit GlobalSearchTimer(double timeout) : timeout_(timeout) {}

  /// Called with the stamp [s] of each scan that waits for an initial pose: true once the timeout has passed
  /// since the first of them (or since the last failed search).
  bool due(double stamp);

  /// The search started at `stamp` [s] found nothing: wait another timeout before the next one.
  void failed(double stamp) { waiting_since_ = stamp; }

 private:
  double timeout_;
  std::optional<double> waiting_since_;  // [s] first scan that waited, or the last failed search
};

}  // namespace grid_puzzle_localization
