#include "global_search_timer.hpp"

namespace grid_puzzle_localization {

bool GlobalSearchTimer::due(double stamp) {
  if (timeout_ <= 0.0) return false;
  if (!waiting_since_) waiting_since_ = stamp;
  return stamp - *waiting_since_ >= timeout_;
}

}  // namespace grid_puzzle_localization
