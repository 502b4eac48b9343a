// The grid puzzle search window (the paper's Eq. 2-5, Table I and Algorithm 2), the C++ twin of
// src/grid_puzzle_localization/provider/window.py and lost_search.py, which document the maths; a pytest replays
// random pose sequences through both and holds their windows and tile deltas equal. No ROS.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace grid_puzzle_localization {

/// Tile index floor(coord / s) along one axis.
std::int64_t tileIndex(double coord, double s);

/// Table I sector 0..7 of a heading in degrees (normalised to [-20, 340); boundaries start a sector).
int sectorOfDegrees(double deg);
/// Table I sector of a heading [rad].
int sectorOf(double theta);
/// Middle of a Table I sector [deg].
double sectorMidDegrees(int sector);
constexpr int kNoSector = -1;

/// Window bounds in tile indices, inclusive.
struct TileBox {
  std::int64_t i_min = 0, i_max = -1, j_min = 0, j_max = -1;
  bool empty() const { return i_min > i_max || j_min > j_max; }
  bool operator==(const TileBox& o) const {
    return i_min == o.i_min && i_max == o.i_max && j_min == o.j_min && j_max == o.j_max;
  }
  bool operator!=(const TileBox& o) const { return !(*this == o); }
};

/// A window around the agent's tile `centre`; `theta` [rad] is NaN and `sector` kNoSector without a heading.
struct Window {
  std::array<std::int64_t, 2> centre{0, 0};
  double theta = 0.0;
  int sector = kNoSector;
  std::array<std::int64_t, 2> u_range{0, 0};
  std::array<std::int64_t, 2> v_range{0, 0};

  TileBox bounds() const {
    return {centre[0] + u_range[0], centre[0] + u_range[1], centre[1] + v_range[0], centre[1] + v_range[1]};
  }
};

/// The window for agent position (x, y) [m] and heading `theta` [rad] (nullopt or non-finite: plain square).
Window computeWindow(double x, double y, std::optional<double> theta, double s, int n, int k);
/// The smallest window holding `window` (when given) and every tile meeting the square of half side `half_side` [m]
/// around (x, y) [m], centred on (x, y)'s tile, without a heading.
Window windowCovering(const std::optional<Window>& window, double x, double y, double half_side, double s);

/// The window parameters (`window/*`); defaults and their documentation: config/grid_puzzle_map_provider.yaml.
struct WindowConfig {
  int n = 25;                             ///< [tiles] half side of the default square
  int k = 20;                             ///< [tiles] extension toward the heading
  double update_distance = 0.0;           ///< [m] recompute after moving farther; 0 = s / 2
  std::string heading_source = "motion";  ///< motion | yaw
  double lookahead_time = 0.0;            ///< [s] centre on position + velocity * lookahead_time
  std::string preset;                     ///< urban | courtyard | "" (use n, k)

  /// The values checked and the preset applied; throws std::invalid_argument naming the bad parameter.
  WindowConfig resolved() const;
  double updateDistanceFor(double s) const { return update_distance > 0.0 ? update_distance : s / 2.0; }
};

/// One pose in the map frame: position [m], time [s], optional yaw [rad] and map-frame velocity [m/s].
struct PoseSample {
  double x = 0.0, y = 0.0, t = 0.0;
  std::optional<double> yaw;
  std::optional<std::array<double, 2>> velocity;
};

/// Algorithm 2's outer loop: when the window is recomputed, and with which heading (window.py's WindowTracker).
class WindowTracker {
 public:
  WindowTracker(const WindowConfig& config, double s);
  /// The recomputed window, or nullopt while the agent has not moved farther than the update distance.
  std::optional<Window> update(const PoseSample& pose);
  /// The next pose recomputes the window wherever it is (the heading is kept).
  void restart() { anchor_.reset(); }
  /// Windows one update ahead, most likely first (straight on, then the two neighbouring sectors).
  std::vector<Window> predictedWindows() const;
  const std::optional<Window>& window() const { return window_; }
  const WindowConfig& config() const { return config_; }
  double updateDistance() const { return update_distance_; }
  double s() const { return s_; }

 private:
  std::array<double, 2> lookaheadPoint(const PoseSample& pose) const;

  WindowConfig config_;
  double s_;
  double update_distance_;
  std::optional<PoseSample> anchor_;
  std::optional<double> theta_;
  std::array<double, 2> centre_point_{0.0, 0.0};
  std::optional<Window> window_;
  double last_step_ = 0.0;
};

/// Where a lost localizer searches: centre [m] (map frame), radius [m], stamp [s].
struct LostSearchRegion {
  double x = 0.0, y = 0.0, radius = 0.0, t = 0.0;
};

/// A hint's search region reaches this many standard deviations of its position (lost_search.py's HINT_SIGMAS).
constexpr double kHintSigmas = 3.0;
/// The search region of a coarse position (`initialpose_hint`): kHintSigmas standard deviations of the larger of its
/// variances [m^2] around it (radius 0 when they are not finite and positive); nullopt for a position that is not
/// finite.
std::optional<LostSearchRegion> hintRegion(double x, double y, double variance_x, double variance_y, double t);

/// The window while the localizer is lost (lost_search.py's LostSearchWindow): the union of the pose's window and
/// the square of half side (search radius + reach), rounded up to kSearchStep and at most max_half_side.
class LostSearchWindow {
 public:
  static constexpr double kSearchStep = 10.0;  ///< [m]
  LostSearchWindow(double max_half_side, double reach, double s)
      : max_half_side_(max_half_side), reach_(reach), s_(s) {}
  /// The window for `region`, or nullopt when `served` is it already; once one is returned the window serves it.
  std::optional<Window> cover(const LostSearchRegion& region, const std::optional<Window>& pose_window,
                              const std::optional<TileBox>& served);
  /// The localizer tracks again; true when a search's window was being served.
  bool end() {
    const bool was = active_;
    active_ = false;
    return was;
  }
  bool active() const { return active_; }
  /// A window that is not the pose's (the whole map of a start without a pose) is served until the localizer tracks.
  void hold() { active_ = true; }

 private:
  double max_half_side_, reach_, s_;
  bool active_ = false;
};

}  // namespace grid_puzzle_localization
