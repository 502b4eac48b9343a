// Replays a synthetic drive through the core Localizer at the scan rate, with the map following the
// vehicle as a window of tiles, and prints one JSON line: per-scan latency percentiles, the worst latency
// while a target update was pending, target update times and peak RSS. No ROS.
// A scan's wait is its latency minus its scan thread's CPU time: the time the thread did not run (preempted by other
// threads and processes, or blocked). worst_wait_during_update_ms against the control's worst_wait_ms separates a
// stall from a scan that simply has more work.
// Mode `repeat` is the control: the first scan, localised from the same initial pose at every scan slot against
// the first window, which never changes. Its work is identical each time, so its latency spread is the
// machine's own (scheduling, frequency, caches, other tenants), the floor under the other modes' p99 / p50.
// Mode `replay` (bench/replay_scenario.py) runs a recording as fast as it goes against the whole map, from the
// first scan's true pose, at the recording's own stamps: for tracking figures, not latency.
//
// Usage: bench_localizer INPUT.bin cloud|tiles|repeat|replay [--tile-size S] [--window N] [--threads T] [--resolution
// R]
//                        [--max-range M] [--max-step-size M] [--coarse-points N] [--coarse-yaw-probe RAD]
//                        [--trace FILE] [--tile-source DIR|URL] [--index-revision REV] [--update-distance M]
//                        [--map-wait-half-side M]
//                        [--map-store-cache DIR] [--cold-start 0|1] [--pace rate|stamps]
// --trace writes one CSV row per scan (latency, NDT iterations, prediction and ground-truth errors, whether the
// match was accepted and the pose published, the localizer's state, lost, the window's tiles in flight and those the
// scan waited for, those in flight within map_wait_half_side of the first scan's true position and of this scan's
// (before the first map is swapped in: all of the first window's there), the pose, the monotonic clock, whether the map
// store answers, the true position) to FILE.
// --cold-start 1: the drive starts as soon as the first window is submitted, without waiting for its tiles (the
// localizer waits for those around the start itself, as from a slow map store); the JSON line then gives the first
// window's tile count and the time until all of it was in the map (first_window). The window follows the pose while
// the localizer tracks, and the start it carries while that waits for its map; the tiles still to load go nearest
// the localizer's focus first (the start, then each tracked scan's prediction).
// --pace stamps: each scan is handed over at its own stamp after the first (a recording's real time, e.g. keyframes
// at irregular intervals) instead of every 1 / rate_hz.
// --tile-source: tiles mode names the window's tiles by reference, as the provider does, in a tile directory that
// `gpm tile` cut from the same map with the same tile size, or at the URL of a map store serving one (fetched into
// --map-store-cache; --index-revision is then the revision of its index.json, as the provider sends it);
// bench/bench_map_store.py runs it behind a delaying proxy.
// --update-distance M: the window is recomputed only once the pose has moved more than M [m] from where it was last
// (the provider's window/update_distance); 0: at every tile the pose crosses. The JSON line's map_worker gives the
// worker thread's CPU time over the drive (after a first window that was waited for) and per metre driven.
// INPUT.bin (little endian) is written by bench/bench_localizer.py:
//   char[8] "GPLBENCH"; f64 rate_hz; u64 n_map; f32 map[n_map][3]; f64 base_T_sensor[16] (row-major);
//   u64 n_imu; f64 imu[n_imu][4] (stamp, gyro x y z in base_link [rad/s]);
//   u64 n_scans; then per scan: f64 stamp; f64 truth[16] (map_T_base, row-major); u64 n; f32 points[n][3];
//   u64 n_times (0 for an instantaneous scan, else n); f32 times[n_times] (capture time after the stamp [s], which
//   the localizer deskews with, as the nodelet does with the cloud's time field)
// Scans are read one at a time between scan slots (outside the timed call), so peak RSS is the localizer's
// and the map's, not the whole recording's. Gyro samples up to a scan's stamp are fed before it, as the
// nodelet's IMU callback would.
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iomanip>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "grid_puzzle_localization/localizer.hpp"
#include "grid_puzzle_localization/provider/tile_directory.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

struct Scan {
  double stamp = 0.0;
  Eigen::Isometry3d truth = Eigen::Isometry3d::Identity();
  gpl::PointCloud points;
  gpl::PointTimes times;  ///< empty, or one per point
};

struct GyroSample {
  double stamp = 0.0;
  Eigen::Vector3d rate = Eigen::Vector3d::Zero();  ///< base frame [rad/s]
};

struct Input {
  double rate_hz = 10.0;
  gpl::PointCloud map;
  Eigen::Isometry3d base_T_sensor = Eigen::Isometry3d::Identity();
  std::vector<GyroSample> gyro;
  std::uint64_t scans = 0;
  std::ifstream rest;  ///< positioned at the first scan
};

template <class T>
T readValue(std::ifstream& in) {
  T v;
  in.read(reinterpret_cast<char*>(&v), sizeof v);
  if (!in) throw std::runtime_error("input file is truncated");
  return v;
}

gpl::PointCloud readCloud(std::ifstream& in) {
  const auto n = readValue<std::uint64_t>(in);
  gpl::PointCloud cloud(n);
  in.read(reinterpret_cast<char*>(cloud.data()), static_cast<std::streamsize>(n * 3 * sizeof(float)));
  if (!in) throw std::runtime_error("input file is truncated");
  return cloud;
}

Eigen::Isometry3d readPose(std::ifstream& in) {
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m(r, c) = readValue<double>(in);
  return Eigen::Isometry3d(m);
}

void readInput(const std::string& path, Input& input) {
  std::ifstream& in = input.rest;
  in.open(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot open " + path);
  char magic[8];
  in.read(magic, 8);
  if (!in || std::memcmp(magic, "GPLBENCH", 8) != 0) throw std::runtime_error(path + " is not a bench input file");
  input.rate_hz = readValue<double>(in);
  input.map = readCloud(in);
  input.base_T_sensor = readPose(in);
  input.gyro.resize(readValue<std::uint64_t>(in));
  for (GyroSample& g : input.gyro) {
    g.stamp = readValue<double>(in);
    for (int k = 0; k < 3; ++k) g.rate(k) = readValue<double>(in);
  }
  input.scans = readValue<std::uint64_t>(in);
  if (input.scans == 0) throw std::runtime_error(path + " holds no scan");
}

Scan readScan(std::ifstream& in) {
  Scan s;
  s.stamp = readValue<double>(in);
  s.truth = readPose(in);
  s.points = readCloud(in);
  const auto n_times = readValue<std::uint64_t>(in);
  if (n_times != 0 && n_times != s.points.size())
    throw std::runtime_error("a scan's point times are neither none nor one per point");
  s.times.resize(n_times);
  in.read(reinterpret_cast<char*>(s.times.data()), static_cast<std::streamsize>(s.times.size() * sizeof(float)));
  if (!in) throw std::runtime_error("input file is truncated");
  return s;
}

using TileKey = std::pair<int, int>;

// The tile's file stem as the tiler names it: its centre [m] ("cx_cy"), from which the map worker gets (i, j).
std::string tileId(const TileKey& k, double s) { return gpl::tileStem(k.first, k.second, s); }

std::map<TileKey, gpl::PointCloud> cutTiles(const gpl::PointCloud& map, double s) {
  std::map<TileKey, gpl::PointCloud> tiles;
  for (const gpl::Point& p : map)
    tiles[{static_cast<int>(std::floor(p.x() / s)), static_cast<int>(std::floor(p.y() / s))}].push_back(p);
  return tiles;
}

std::set<TileKey> window(const std::map<TileKey, gpl::PointCloud>& tiles, const Eigen::Vector3d& at, double s, int n) {
  const int ci = static_cast<int>(std::floor(at.x() / s));
  const int cj = static_cast<int>(std::floor(at.y() / s));
  std::set<TileKey> w;
  for (int i = ci - n; i <= ci + n; ++i)
    for (int j = cj - n; j <= cj + n; ++j)
      if (tiles.count({i, j})) w.insert({i, j});
  return w;
}

// CPU time of the calling thread [ms]: the scan's own work, without the time other processes took the core.
double threadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

// CLOCK_MONOTONIC [s], as Python's time.monotonic() reads it: a trace row can be set against events in another process.
double monotonicSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// Angle [rad] of the rotation between the orientations of a and b.
double rotationAngle(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b) {
  return Eigen::AngleAxisd(a.linear().transpose() * b.linear()).angle();
}

// Peak resident set of this address space [MB] (VmHWM). getrusage's ru_maxrss would not do: Linux carries it
// across execve, so it starts at the peak of the Python process that forked this one.
double peakRssMb() {
  std::ifstream status("/proc/self/status");
  for (std::string line; std::getline(status, line);)
    if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;  // the value is in kB
  return 0.0;
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const double pos = q * static_cast<double>(v.size() - 1);
  const auto lo = static_cast<std::size_t>(std::floor(pos));
  const auto hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (pos - static_cast<double>(lo)) * (v[hi] - v[lo]);
}

std::chrono::steady_clock::duration scanPeriod(const Input& input) {
  return std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(1.0 / input.rate_hz));
}

// The control mode (see the top of the file); prints its JSON line.
int repeatFirstScan(gpl::Localizer& loc, const Input& input, const Scan& scan) {
  std::vector<double> latency, cpu, wait;
  double first_scan_ms = 0.0;
  int iterations = 0;
  auto next = std::chrono::steady_clock::now();
  for (std::uint64_t i = 0; i < input.scans; ++i) {
    loc.setInitialPose(scan.truth);
    std::this_thread::sleep_until(next);
    next += scanPeriod(input);
    const double cpu_start = threadCpuMs();
    const gpl::LocalizerOutput out = loc.processScan(scan.stamp + static_cast<double>(i) / input.rate_hz, scan.points,
                                                     input.base_T_sensor, &scan.times);
    const double cpu_ms = threadCpuMs() - cpu_start;
    iterations = out.ndt.iterations;
    if (i == 0) {  // swaps in the map: reported on its own, as in the drive
      first_scan_ms = out.scan_ms;
      continue;
    }
    cpu.push_back(cpu_ms);
    latency.push_back(out.scan_ms);
    wait.push_back(out.scan_ms - cpu_ms);
  }
  std::printf(
      "{\"mode\": \"repeat\", \"scans\": %zu, \"first_scan_ms\": %.2f, \"latency_ms\": {\"p50\": %.2f, \"p95\": %.2f, "
      "\"p99\": %.2f, "
      "\"max\": %.2f}, \"p99_over_p50\": %.2f, \"scan_thread_cpu_ms\": {\"p50\": %.2f, \"p99\": %.2f}, "
      "\"worst_wait_ms\": %.2f, \"iterations_per_scan\": %d, \"work\": \"the first scan from the same pose at every "
      "slot, fixed map\"}\n",
      static_cast<std::size_t>(input.scans), first_scan_ms, percentile(latency, 0.5), percentile(latency, 0.95),
      percentile(latency, 0.99), percentile(latency, 1.0), percentile(latency, 0.99) / percentile(latency, 0.5),
      percentile(cpu, 0.5), percentile(cpu, 0.99), percentile(wait, 1.0), iterations);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(
        stderr,
        "usage: %s INPUT.bin cloud|tiles|repeat|replay [--tile-size S] [--window N] [--threads T] [--resolution R] "
        "[--max-range M] [--max-step-size M] [--coarse-points N] [--coarse-yaw-probe RAD] [--trace FILE] "
        "[--update-distance M] [--map-wait-half-side M] "
        "[--tile-source DIR|URL] [--index-revision REV] [--map-store-cache DIR] [--cold-start 0|1] "
        "[--pace rate|stamps]\n",
        argv[0]);
    return 2;
  }
  const std::string mode = argv[2];
  if (mode != "cloud" && mode != "tiles" && mode != "repeat" && mode != "replay") {
    std::fprintf(stderr, "bench_localizer: mode must be cloud, tiles, repeat or replay (got '%s')\n", mode.c_str());
    return 2;
  }
  double tile_size = 10.0;
  int half_window = 3;
  double update_distance = 0.0;  // [m] 0: the window follows every tile the pose crosses
  int threads = -1;              // -1: the LocalizerConfig default
  gpl::LocalizerConfig config;
  // The scans come as fast as they are matched, not in real time: a search answers within the scan it searches,
  // so a replay gives the same answer every run.
  config.lost.background_search = false;
  gpl::MapStoreConfig store_config;
  std::string trace_path, tile_source, index_revision, pace = "rate";
  bool cold_start = false;
  for (int i = 3; i + 1 < argc; i += 2) {
    const std::string opt = argv[i];
    if (opt == "--tile-size")
      tile_size = std::stod(argv[i + 1]);
    else if (opt == "--window")
      half_window = std::stoi(argv[i + 1]);
    else if (opt == "--update-distance")
      update_distance = std::stod(argv[i + 1]);
    else if (opt == "--map-wait-half-side")
      config.map_wait_half_side = std::stod(argv[i + 1]);
    else if (opt == "--threads")
      threads = std::stoi(argv[i + 1]);
    else if (opt == "--resolution")
      config.ndt.resolution = std::stod(argv[i + 1]);
    else if (opt == "--max-step-size")
      config.ndt.max_step_size = std::stod(argv[i + 1]);
    else if (opt == "--coarse-points")
      config.ndt.coarse_points = std::stoi(argv[i + 1]);
    else if (opt == "--coarse-yaw-probe")
      config.ndt.coarse_yaw_probe = std::stod(argv[i + 1]);
    else if (opt == "--max-range")
      config.preprocess.max_range = std::stod(argv[i + 1]);
    else if (opt == "--trace")
      trace_path = argv[i + 1];
    else if (opt == "--tile-source")
      tile_source = argv[i + 1];
    else if (opt == "--index-revision")
      index_revision = argv[i + 1];
    else if (opt == "--map-store-cache")
      store_config.cache_dir = argv[i + 1];
    else if (opt == "--cold-start")
      cold_start = std::stoi(argv[i + 1]) != 0;
    else if (opt == "--pace")
      pace = argv[i + 1];
    else {
      std::fprintf(stderr, "bench_localizer: unknown option %s\n", opt.c_str());
      return 2;
    }
  }
  if (pace != "rate" && pace != "stamps") {
    std::fprintf(stderr, "bench_localizer: --pace must be rate or stamps (got '%s')\n", pace.c_str());
    return 2;
  }
  Input input;
  Scan scan;
  try {
    readInput(argv[1], input);
    scan = readScan(input.rest);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_localizer: %s\n", e.what());
    return 2;
  }

  if (threads >= 0) config.ndt.threads = threads;
  gpl::Localizer loc(config);
  loc.map().setMapStoreConfig(store_config);
  const auto tiles = cutTiles(input.map, tile_size);

  // The map follows the localizer's own pose, as the tile provider follows odom. cloud mode gets the
  // merged window as one cloud (a full rebuild per change), tiles mode gets the delta.
  std::set<TileKey> loaded;
  std::size_t updates = 0;
  const bool replay = mode == "replay";
  std::optional<Eigen::Vector3d> centre;  // where the window was last recomputed
  auto follow = [&](const Eigen::Vector3d& at) {
    if (replay) {
      if (updates++ == 0) loc.map().submit(gpl::MapChange::fullCloud(input.map));
      return;
    }
    if (centre && update_distance > 0.0 && (at - *centre).head<2>().norm() <= update_distance) return;
    centre = at;
    const std::set<TileKey> want = window(tiles, at, tile_size, half_window);
    if (want == loaded) return;
    if (mode == "cloud") {
      gpl::PointCloud merged;
      for (const TileKey& k : want) merged.insert(merged.end(), tiles.at(k).begin(), tiles.at(k).end());
      loc.map().submit(gpl::MapChange::fullCloud(std::move(merged)));
    } else {
      std::vector<TileKey> entering;
      std::vector<std::string> leaving;
      for (const TileKey& k : want)
        if (!loaded.count(k)) entering.push_back(k);
      for (const TileKey& k : loaded)
        if (!want.count(k)) leaving.push_back(tileId(k, tile_size));
      if (!tile_source.empty()) {  // by reference, as the provider sends them
        gpl::TileFileChange files;
        files.dir = tile_source;
        files.index_revision = index_revision;
        files.reset = loaded.empty();
        for (const TileKey& k : entering) files.added.push_back(tileId(k, tile_size));
        files.removed = std::move(leaving);
        loc.map().submit(gpl::MapChange::tileFiles(tile_size, std::move(files)));
      } else {
        std::vector<gpl::TileCloud> added;
        for (const TileKey& k : entering) added.push_back({tileId(k, tile_size), tiles.at(k)});
        loc.map().submit(gpl::MapChange::tiles(loaded.empty(), tile_size, std::move(added), std::move(leaving)));
      }
    }
    loaded = want;
    ++updates;
  };

  follow(scan.truth.translation());
  const std::size_t first_window_tiles = loaded.size();
  cold_start = cold_start && mode != "repeat";
  if (!cold_start) loc.map().waitIdle();
  if (mode == "repeat") return repeatFirstScan(loc, input, scan);
  loc.setInitialPose(scan.truth);
  const Eigen::Vector2d start_xy = scan.truth.translation().head<2>();
  double first_window_load_ms = -1.0;  // the first whole snapshot's update time (cold start)
  // The first window's tiles that meet the square of half side map_wait_half_side about the start (as
  // TilesInFlight::within counts them): all in flight until the localizer has a map.
  gpl::TilesInFlight first_window;
  first_window.tile_size = tile_size;
  for (const TileKey& k : loaded) first_window.keys.push_back({k.first, k.second});
  const auto first_window_tiles_near = [&](const Eigen::Vector2d& xy) {
    return first_window.within(xy, config.map_wait_half_side);
  };
  const std::size_t start_square_tiles = first_window_tiles_near(start_xy);
  bool have_map = false;  // a target was swapped in
  // The map worker's CPU time before the drive (the first window, when it was waited for): the drive's own is the rest.
  const double worker_cpu_before_ms = loc.map().stats().worker_cpu_ms;

  std::ofstream trace;
  if (!trace_path.empty()) {
    trace.open(trace_path);
    if (!trace) {
      std::fprintf(stderr, "bench_localizer: cannot write the trace file %s\n", trace_path.c_str());
      return 2;
    }
    trace << "scan,stamp_s,scan_ms,align_ms,cpu_ms,iterations,evaluations,coarse_evaluations,source_points,"
             "update_pending,prediction_to_match_m,prediction_to_match_rad,prediction_error_m,prediction_error_rad,"
             "error_m,error_rad,truth_yaw_rate_rad_s,accepted,published,hypotheses,global_search,nvtl,"
             "global_search_reason,state,lost,tiles_in_flight,tiles_awaited,start_tiles_in_flight,"
             "scan_square_tiles_in_flight,x,y,yaw,"
             "monotonic_s,map_store_reachable,truth_x,truth_y\n";
  }
  // latency_loading: scans that overlapped a target update and ran no branch-and-bound search (a search, e.g. on
  // the first scan without a measured velocity, costs tens of ms whatever the map does).
  std::vector<double> latency, latency_pending, latency_loading, latency_quiet, cpu, update_ms, errors;
  std::vector<double> wait_loading;  // scan_ms - cpu_ms of latency_loading's scans: time the scan thread did not run
  std::size_t searches = 0;
  double first_scan_ms = 0.0;
  std::size_t rejected = 0;
  double distance = 0.0;  // [m] driven (ground truth)
  std::uint64_t generation = loc.map().stats().generation;
  auto next = std::chrono::steady_clock::now();
  const auto drive_start = next;
  const double first_stamp = scan.stamp;
  std::size_t gyro_fed = 0;
  Eigen::Isometry3d last_truth = scan.truth;
  double last_stamp = scan.stamp;
  for (std::uint64_t i = 0; i < input.scans; ++i) {
    if (i > 0) {
      last_truth = scan.truth;
      last_stamp = scan.stamp;
      scan = readScan(input.rest);
    }
    for (; gyro_fed < input.gyro.size() && input.gyro[gyro_fed].stamp <= scan.stamp; ++gyro_fed)
      loc.addGyro(input.gyro[gyro_fed].stamp, input.gyro[gyro_fed].rate);
    if (!replay && pace == "stamps") {
      std::this_thread::sleep_until(drive_start + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                                      std::chrono::duration<double>(scan.stamp - first_stamp)));
    } else if (!replay) {
      std::this_thread::sleep_until(next);
      next += scanPeriod(input);
    }
    const double cpu_start = threadCpuMs();
    const gpl::LocalizerOutput out = loc.processScan(scan.stamp, scan.points, input.base_T_sensor, &scan.times);
    const double cpu_ms = threadCpuMs() - cpu_start;
    have_map = have_map || out.map_swapped;
    // The first scan swaps in the initial map and converges from the initial pose: reported on its own.
    if (i == 0) {
      first_scan_ms = out.scan_ms;
    } else {
      cpu.push_back(cpu_ms);
      latency.push_back(out.scan_ms);
      const bool pending = out.map_update_pending || out.map_swapped;
      (pending ? latency_pending : latency_quiet).push_back(out.scan_ms);
      if (pending && !out.global_search) {
        latency_loading.push_back(out.scan_ms);
        wait_loading.push_back(out.scan_ms - cpu_ms);
      }
      searches += out.global_search;
    }
    if (trace.is_open()) {
      const double dt = scan.stamp - last_stamp;
      const double yaw_rate = dt > 0.0 ? rotationAngle(last_truth, scan.truth) / dt : 0.0;
      std::string reason = out.global_search_reason;
      std::replace(reason.begin(), reason.end(), '"', '\'');
      trace << i << ',' << std::fixed << std::setprecision(3) << scan.stamp << std::defaultfloat << ',' << out.scan_ms
            << ',' << out.align_ms << ',' << cpu_ms << ',' << out.ndt.iterations << ',' << out.ndt.evaluations << ','
            << out.ndt.coarse_evaluations << ',' << out.ndt.source_points << ','
            << (out.map_update_pending || out.map_swapped) << ','
            << (out.prediction.translation() - out.pose.translation()).norm() << ','
            << rotationAngle(out.prediction, out.pose) << ','
            << (out.prediction.translation() - scan.truth.translation()).norm() << ','
            << rotationAngle(out.prediction, scan.truth) << ','
            << (out.pose.translation() - scan.truth.translation()).norm() << ',' << rotationAngle(out.pose, scan.truth)
            << ',' << yaw_rate << ',' << out.match_accepted << ',' << out.publish << ',' << out.hypotheses << ','
            << out.global_search << ',' << out.ndt.nvtl << ",\"" << reason << "\"," << gpl::toString(out.state) << ','
            << out.lost << ',' << out.tiles_in_flight << ',' << out.tiles_awaited << ','
            << (have_map ? loc.tilesAwaited(start_xy, config.map_wait_half_side) : start_square_tiles) << ','
            << (have_map ? loc.tilesAwaited(scan.truth.translation().head<2>(), config.map_wait_half_side)
                         : first_window_tiles_near(scan.truth.translation().head<2>()))
            << ',' << std::setprecision(9) << out.pose.translation().x() << ',' << out.pose.translation().y() << ','
            << std::atan2(out.pose.linear()(1, 0), out.pose.linear()(0, 0)) << ',' << monotonicSeconds() << ','
            << loc.map().stats().map_store_reachable << ',' << scan.truth.translation().x() << ','
            << scan.truth.translation().y() << std::defaultfloat << std::setprecision(6) << '\n';
    }
    if (!out.match_accepted) ++rejected;
    // A scan that waited for its map (cold start) has no pose.
    if (out.state == gpl::LocalizerState::kTracking)
      errors.push_back((out.pose.translation() - scan.truth.translation()).norm());
    distance += (scan.truth.translation() - last_truth.translation()).norm();
    const gpl::MapUpdateStats stats = loc.map().stats();
    if (stats.generation != generation) {
      generation = stats.generation;
      update_ms.push_back(stats.update_ms);
      if (first_window_load_ms < 0.0) first_window_load_ms = stats.update_ms;
    }
    // The window follows the pose, and a start carried while its map arrives, as the provider does.
    if (out.state == gpl::LocalizerState::kTracking)
      follow(out.pose.translation());
    else if (out.start_pending)
      follow(out.prediction.translation());
  }
  loc.map().waitIdle();
  const gpl::MapUpdateStats end = loc.map().stats();
  if (end.generation != generation) update_ms.push_back(end.update_ms);
  if (first_window_load_ms < 0.0 && end.generation != generation) first_window_load_ms = end.update_ms;
  const std::vector<std::string> failed = loc.map().takeErrors();  // e.g. tiles a map store could not serve

  double mean_error = 0.0;
  for (double e : errors) mean_error += e / static_cast<double>(errors.size());
  std::printf(
      "{\"mode\": \"%s\", \"scans\": %zu, \"first_scan_ms\": %.2f, \"latency_ms\": {\"p50\": %.2f, \"p95\": %.2f, "
      "\"p99\": %.2f, \"max\": "
      "%.2f}, \"p99_over_p50\": %.2f, "
      "\"worst_latency_during_update_ms\": %.2f, \"scans_during_update\": %zu, \"p50_latency_during_update_ms\": %.2f, "
      "\"worst_latency_during_update_without_search_ms\": %.2f, \"worst_wait_during_update_ms\": %.2f, "
      "\"searches\": %zu, "
      "\"p99_latency_without_update_ms\": %.2f, \"scan_thread_cpu_ms\": {\"p50\": %.2f, \"p99\": %.2f}, "
      "\"target_updates\": %zu, "
      "\"target_update_ms\": {\"median\": %.1f, \"max\": %.1f}, \"rejected_matches\": %zu, "
      "\"translation_error_m\": {\"mean\": %.4f, \"max\": %.4f}, \"map_points\": %zu, \"tile_size_m\": %.1f, "
      "\"window_tiles\": %d, \"ndt_threads\": %d, \"map_update_threads\": %d, \"gyro_samples\": %zu, "
      "\"peak_rss_mb\": %.1f, \"distance_m\": %.1f, \"map_store\": {\"tiles_fetched\": %zu, \"bytes_fetched\": %llu, "
      "\"reachable\": %s}, \"map_update_failures\": %zu, \"cold_start\": %s, \"pace\": \"%s\", "
      "\"first_window\": {\"tiles\": %zu, \"start_square_tiles\": %zu, \"load_ms\": %.1f}, "
      "\"update_distance_m\": %.2f, \"map_worker\": {\"cpu_ms\": %.1f, \"read_cpu_ms\": %.1f, \"fold_cpu_ms\": %.1f, "
      "\"tiles_read\": %zu, \"cpu_ms_per_m\": %.3f}}\n",
      mode.c_str(), static_cast<std::size_t>(input.scans), first_scan_ms, percentile(latency, 0.5),
      percentile(latency, 0.95), percentile(latency, 0.99), percentile(latency, 1.0),
      percentile(latency, 0.99) / percentile(latency, 0.5), percentile(latency_pending, 1.0), latency_pending.size(),
      percentile(latency_pending, 0.5), percentile(latency_loading, 1.0), percentile(wait_loading, 1.0), searches,
      percentile(latency_quiet, 0.99), percentile(cpu, 0.5), percentile(cpu, 0.99), updates, percentile(update_ms, 0.5),
      percentile(update_ms, 1.0), rejected, mean_error, percentile(errors, 1.0), input.map.size(), tile_size,
      (2 * half_window + 1) * (2 * half_window + 1), config.ndt.threads, config.map_update_threads, input.gyro.size(),
      peakRssMb(), distance, end.map_store_fetched, static_cast<unsigned long long>(end.map_store_bytes),
      end.map_store_reachable ? "true" : "false", failed.size(), cold_start ? "true" : "false", pace.c_str(),
      first_window_tiles, start_square_tiles, cold_start ? first_window_load_ms : 0.0, update_distance,
      end.worker_cpu_ms, end.tile_read_cpu_ms, end.tile_fold_cpu_ms, static_cast<std::size_t>(end.tiles_read),
      distance > 0.0 ? (end.worker_cpu_ms - worker_cpu_before_ms) / distance : 0.0);
  return 0;
}
