// Command-line option values of the package's C++ tools (ndt_align, global_localize): a bad value is a
// UsageError naming the option and the text, so `main` can print it with the usage and exit 2.
#pragma once

#include <cmath>
#include <cstdlib>
#include <stdexcept>
#include <string>

namespace grid_puzzle_localization::tools {

struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// The finite number `text` is, else UsageError naming `option`.
inline double number(const std::string& option, const std::string& text) {
  std::size_t used = 0;
  double v = 0.0;
  try {
    v = std::stod(text, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != text.size() || !std::isfinite(v))
    throw UsageError("option " + option + " expects a finite number, got '" + text + "'");
  return v;
}

/// The integer (|v| <= 1e9) `text` is, else UsageError naming `option`.
inline int integer(const std::string& option, const std::string& text) {
  const double v = number(option, text);
  if (v != std::floor(v) || std::abs(v) > 1e9)
    throw UsageError("option " + option + " expects an integer, got '" + text + "'");
  return static_cast<int>(v);
}

}  // namespace grid_puzzle_localization::tools
