#include "warning_throttle.hpp"

#include <cctype>

namespace grid_puzzle_localization {

bool WarningThrottle::pass(const std::string& warning, double now) {
  std::string kind;
  for (char ch : warning)
    if (!std::isdigit(static_cast<unsigned char>(ch))) kind += ch;
  const auto it = last_log_.find(kind);
  if (it != last_log_.end() && now - it->second < period_) return false;
  last_log_[kind] = now;
  return true;
}

}  // namespace grid_puzzle_localization
