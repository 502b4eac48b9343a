// Memory and CPU of the localizer as the map grows: the same drive through maps of F times a base map's area
// (the base repeated on a sqrt(F) x sqrt(F) grid), once with the whole map (global: the PCD read by the map
// worker, as map_source pcd) and once with a grid puzzle window of tile files read by reference (as
// map_source tiles), the window served in the same process by the provider nodelet's core (WindowServer), as the
// nodelet runs in the localizer's manager, so its memory counts. No ROS. Driven by bench/bench_scaling.py, one process
// per map size and mode so that each peak RSS is that run's alone.
//
// Usage:
//   bench_scaling prepare BASE.pcd FACTOR DIR TILE_SIZE SECONDS
//       writes DIR/global.pcd, DIR/tiles/<cx>_<cy>.pcd with their index.json and the drive's scans (DIR/scans.bin)
//   bench_scaling run DIR global|tiles TILE_SIZE N K SECONDS
//   bench_scaling load DIR TILE_SIZE REPEATS   every tile of DIR/tiles into an empty target, one map thread
// `run` prints one JSON object: peak RSS, the map's memory (RSS with the first map minus RSS before it), mean
// CPU per scan (scan thread, and the whole process including the map worker), map load time and throughput.
// The drive runs through the first copy at 10 m/s, 10 Hz; scans are the base map's points within 40 m of the pose
// (every third one, 1 cm noise), made by `prepare` and read one at a time by `run`.
#include <sys/resource.h>
#include <sys/stat.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <random>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "grid_puzzle_localization/localizer.hpp"
#include "grid_puzzle_localization/pcd_reader.hpp"
#include "grid_puzzle_localization/provider/window_server.hpp"
#include "tile_files.hpp"

namespace gpl = grid_puzzle_localization;
namespace fs = std::filesystem;

namespace {

constexpr double kRate = 10.0;   // [Hz] scans
constexpr double kSpeed = 10.0;  // [m/s]
constexpr float kRange = 40.0f;  // [m] scan radius

double procStatusMb(const char* field) {
  std::ifstream in("/proc/self/status");
  std::string line;
  const std::string key = std::string(field) + ":";
  while (std::getline(in, line))
    if (line.compare(0, key.size(), key) == 0) return std::atof(line.c_str() + key.size()) / 1024.0;
  return NAN;
}

double cpuSeconds(clockid_t clock) {
  timespec ts{};
  clock_gettime(clock, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

struct Extent {
  float x0, y0, x1, y1;
};

Extent extentOf(const gpl::PointCloud& cloud) {
  Extent e{INFINITY, INFINITY, -INFINITY, -INFINITY};
  for (const auto& p : cloud) {
    e.x0 = std::min(e.x0, p.x());
    e.y0 = std::min(e.y0, p.y());
    e.x1 = std::max(e.x1, p.x());
    e.y1 = std::max(e.y1, p.y());
  }
  return e;
}

// The drive: from 40 m inside the west edge of the base map (the first copy), at mid-height, heading 30 degrees.
Eigen::Isometry3d drivePose(const Extent& base, double t) {
  const double yaw = M_PI / 6;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(base.x0 + 40.0, 0.5 * (base.y0 + base.y1), 1.8) +
                       kSpeed * t * Eigen::Vector3d(std::cos(yaw), std::sin(yaw), 0.0);
  pose.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return pose;
}

// Scans of the drive cut from the base map (every third point within kRange, 1 cm noise), written to `path` as
// u64 count then count x y z float32 per scan: the run reads them one at a time, outside its memory and clock.
void writeScans(const gpl::PointCloud& base, const Extent& e, double seconds, const std::string& path) {
  std::ofstream out(path, std::ios::binary);
  std::mt19937 rng(7);
  std::normal_distribution<float> noise(0.0f, 0.01f);
  const int scans = static_cast<int>(seconds * kRate);
  const Eigen::Vector3d a = drivePose(e, 0.0).translation(), b = drivePose(e, seconds).translation();
  gpl::PointCloud corridor;  // the points any scan can reach
  for (const gpl::Point& p : base)
    if (p.x() >= std::min(a.x(), b.x()) - kRange && p.x() <= std::max(a.x(), b.x()) + kRange &&
        p.y() >= std::min(a.y(), b.y()) - kRange && p.y() <= std::max(a.y(), b.y()) + kRange)
      corridor.push_back(p);
  for (int c = 0; c < scans; ++c) {
    const Eigen::Isometry3f inv = drivePose(e, c / kRate).inverse().cast<float>();
    gpl::PointCloud scan;
    for (std::size_t p = c % 3; p < corridor.size(); p += 3) {
      const gpl::Point q = inv * corridor[p];
      if (q.norm() < kRange) scan.push_back(q + gpl::Point(noise(rng), noise(rng), noise(rng)));
    }
    const std::uint64_t n = scan.size();
    out.write(reinterpret_cast<const char*>(&n), sizeof n);
    out.write(reinterpret_cast<const char*>(scan.data()), n * sizeof(gpl::Point));
  }
  if (!out) throw std::runtime_error("cannot write " + path);
}

gpl::PointCloud readScan(std::ifstream& in) {
  std::uint64_t n = 0;
  in.read(reinterpret_cast<char*>(&n), sizeof n);
  gpl::PointCloud scan(n);
  in.read(reinterpret_cast<char*>(scan.data()), n * sizeof(gpl::Point));
  if (!in) throw std::runtime_error("scans file ends early");
  return scan;
}

// A minimal tile index (what the provider reads: format, version, grid size and the keys in order), as `gpm tile`
// writes a full one beside the tiles.
void writeIndex(const std::string& tile_dir, const std::set<std::pair<long, long>>& keys, double s) {
  std::ofstream out(tile_dir + "/index.json");
  out << "{\"format\": \"grid_puzzle_tiles\", \"version\": 1, \"grid_size\": " << s << ", \"tiles\": [";
  const char* sep = "";
  for (const auto& k : keys) {
    out << sep << "{\"key\": [" << k.first << ", " << k.second << "]}";
    sep = ", ";
  }
  out << "]}\n";
  if (!out) throw std::runtime_error("cannot write " + tile_dir + "/index.json");
}

// Copies are one whole number of tiles apart, so no tile holds points of two copies.
double period(float lo, float hi, double s) { return std::ceil((hi - lo) / s + 1.0) * s; }

int prepare(const std::string& base_path, int factor, const std::string& dir, double s, double seconds) {
  const gpl::PointCloud base = gpl::readPcdXyz(base_path);
  const int side = static_cast<int>(std::lround(std::sqrt(factor)));
  if (side * side != factor) throw std::invalid_argument("FACTOR must be a square (1, 4, 16, ...)");
  const Extent e = extentOf(base);
  const double px = period(e.x0, e.x1, s), py = period(e.y0, e.y1, s);
  fs::create_directories(dir + "/tiles");
  std::set<std::pair<long, long>> keys;
  std::ofstream global(dir + "/global.pcd", std::ios::binary);
  const std::size_t n = base.size() * factor;
  global << "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH " << n
         << "\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS " << n << "\nDATA binary\n";
  for (int a = 0; a < side; ++a)
    for (int b = 0; b < side; ++b) {
      gpl::PointCloud copy = base;
      const gpl::Point offset(static_cast<float>(a * px), static_cast<float>(b * py), 0.0f);
      for (auto& p : copy) p += offset;
      global.write(reinterpret_cast<const char*>(copy.data()), copy.size() * sizeof(gpl::Point));
      gpl::test::writeTiles(dir + "/tiles", gpl::test::cutTileStems(copy, s));
      for (const auto& p : copy)
        keys.emplace(static_cast<long>(std::floor(p.x() / s)), static_cast<long>(std::floor(p.y() / s)));
    }
  writeIndex(dir + "/tiles", keys, s);
  if (!global) throw std::runtime_error("cannot write " + dir + "/global.pcd");
  std::ofstream(dir + "/extent.txt") << e.x0 << ' ' << e.y0 << ' ' << e.x1 << ' ' << e.y1 << '\n';  // of the base
  writeScans(base, e, seconds, dir + "/scans.bin");
  return 0;
}

std::size_t pcdPoints(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line))
    if (line.compare(0, 7, "POINTS ") == 0) return std::stoull(line.substr(7));
  throw std::runtime_error(path + ": no POINTS line");
}

int run(const std::string& dir, const std::string& mode, double s, int n, int k, double seconds) {
  const bool tiles = mode == "tiles";
  if (!tiles && mode != "global") throw std::invalid_argument("mode must be global or tiles");
  gpl::LocalizerConfig config;
  config.preprocess.deskew = false;
  const int scans = static_cast<int>(seconds * kRate);
  const std::string tile_dir = dir + "/tiles";
  Extent base{};
  std::ifstream(dir + "/extent.txt") >> base.x0 >> base.y0 >> base.x1 >> base.y1;
  const auto truthAt = [&](double t) { return drivePose(base, t); };
  std::ifstream scan_file(dir + "/scans.bin", std::ios::binary);

  const double rss_before = procStatusMb("VmRSS");
  gpl::Localizer loc(config);
  std::optional<gpl::WindowServer> provider;  // tiles: the provider nodelet's core, in this process as in the manager
  std::size_t updates = 0;
  const auto stems = [s](const std::vector<gpl::TileKey>& keys) {
    std::vector<std::string> out;
    for (const gpl::TileKey& key : keys) out.push_back(gpl::tileStem(key.i, key.j, s));
    return out;
  };
  auto follow = [&](const Eigen::Vector3d& at, double t) {
    gpl::PoseSample pose;
    pose.x = at.x();
    pose.y = at.y();
    pose.t = t;
    const std::optional<gpl::Served> served = provider->onPose(pose);  // the s/2 update rule, the heading
    if (!served) return;
    gpl::TileFileChange change;
    change.dir = tile_dir;
    change.index_revision = provider->tiles().revision();
    change.reset = served->first;
    change.added = stems(served->delta.added);
    change.removed = stems(served->delta.removed);
    change.prefetch = stems(served->delta.prefetch);
    loc.map().submit(gpl::MapChange::tileFiles(s, std::move(change)));
    ++updates;
  };
  const auto load_start = std::chrono::steady_clock::now();
  if (tiles) {
    gpl::WindowConfig window;
    window.n = n;
    window.k = k;
    provider.emplace(window, 0.0, gpl::openTileDirectory(tile_dir, 0.0));
    follow(truthAt(0.0).translation(), 0.0);
  } else {
    loc.map().submit(gpl::MapChange::pcdFile(dir + "/global.pcd"));
  }
  loc.map().waitIdle();
  const double load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - load_start).count();
  const gpl::MapUpdateStats first = loc.map().stats();
  for (const std::string& e : loc.map().takeErrors()) std::fprintf(stderr, "bench_scaling: %s\n", e.c_str());
  const double rss_map = procStatusMb("VmRSS");

  loc.setInitialPose(truthAt(0.0));
  double scan_cpu = 0.0, worst_error = 0.0;
  int tracked = 0;
  const double process_cpu_start = cpuSeconds(CLOCK_PROCESS_CPUTIME_ID);
  for (int c = 0; c < scans; ++c) {
    const double t = c / kRate;
    if (tiles) follow(truthAt(t).translation(), t);
    const gpl::PointCloud scan = readScan(scan_file);
    const double cpu0 = cpuSeconds(CLOCK_THREAD_CPUTIME_ID);
    const gpl::LocalizerOutput out = loc.processScan(t, scan, Eigen::Isometry3d::Identity());
    scan_cpu += cpuSeconds(CLOCK_THREAD_CPUTIME_ID) - cpu0;
    if (out.state == gpl::LocalizerState::kTracking && out.match_accepted) {
      ++tracked;
      worst_error = std::max(worst_error, (out.pose.translation() - truthAt(t).translation()).norm());
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));  // leave the worker its slot, as between scans
  }
  loc.map().waitIdle();
  const double process_cpu = cpuSeconds(CLOCK_PROCESS_CPUTIME_ID) - process_cpu_start;
  const gpl::MapUpdateStats st = loc.map().stats();
  const double load_points = tiles ? static_cast<double>(st.tile_points_read) : static_cast<double>(first.points);
  const double load_ms = tiles ? st.tile_read_ms + st.tile_fold_ms : first.update_ms;
  std::printf(
      "{\"mode\": \"%s\", \"map_points\": %zu, \"target_points_first\": %zu, \"target_voxels_first\": %zu, "
      "\"tile_aligned\": %s, \"peak_rss_mb\": %.1f, \"rss_before_map_mb\": %.1f, \"map_memory_mb\": %.1f, "
      "\"first_map_s\": %.3f, \"scans\": %d, \"tracked\": %d, \"worst_error_m\": %.4f, "
      "\"scan_cpu_ms_mean\": %.2f, \"process_cpu_ms_per_scan\": %.2f, \"map_updates\": %zu, \"tiles_read\": %zu, "
      "\"cache_hits\": %zu, \"load_points\": %.0f, \"load_ms\": %.1f, \"load_mpoints_per_s\": %.2f, "
      "\"tile_read_ms\": %.1f, \"tile_fold_ms\": %.1f, \"rss_end_mb\": %.1f, \"voxel_storage_mb\": %.1f, "
      "\"voxels_end\": %zu, \"cache_mb\": %.1f}\n",
      mode.c_str(), pcdPoints(dir + "/global.pcd"), first.points, first.voxels, st.tile_aligned ? "true" : "false",
      procStatusMb("VmHWM"), rss_before, rss_map - rss_before, load_s, scans, tracked, worst_error,
      1e3 * scan_cpu / scans, 1e3 * process_cpu / scans, updates, st.tiles_read, st.cache_hits, load_points, load_ms,
      load_ms > 0 ? load_points / load_ms / 1e3 : 0.0, st.tile_read_ms, st.tile_fold_ms, procStatusMb("VmRSS"),
      st.map_bytes / 1048576.0, st.voxels, st.cache_bytes / 1048576.0);
  return 0;
}

// Loading throughput: all tile files of a directory read and folded by a fresh map worker (one OpenMP thread),
// the median of REPEATS runs (the files are in the page cache after the first).
int load(const std::string& dir, double s, int repeats) {
  gpl::TileFileChange change;
  change.dir = dir + "/tiles";
  change.index_revision = "1";
  change.reset = true;
  for (const auto& entry : fs::directory_iterator(change.dir))
    if (entry.path().extension() == ".pcd") change.added.push_back(entry.path().stem().string());
  std::vector<double> read_ms, fold_ms, read_cpu_ms, fold_cpu_ms;
  std::size_t points = 0;
  for (int r = 0; r < repeats; ++r) {
    gpl::VoxelMapParams params;
    params.threads = 1;
    gpl::MapUpdateWorker worker(params);
    worker.submit(gpl::MapChange::tileFiles(s, change));
    worker.waitIdle();
    const gpl::MapUpdateStats st = worker.stats();
    for (const std::string& e : worker.takeErrors()) std::fprintf(stderr, "bench_scaling: %s\n", e.c_str());
    read_ms.push_back(st.tile_read_ms);
    fold_ms.push_back(st.tile_fold_ms);
    read_cpu_ms.push_back(st.tile_read_cpu_ms);
    fold_cpu_ms.push_back(st.tile_fold_cpu_ms);
    points = st.tile_points_read;
  }
  const auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  const double read = median(read_ms), fold = median(fold_ms);
  const double read_cpu = median(read_cpu_ms), fold_cpu = median(fold_cpu_ms);
  std::printf(
      "{\"mode\": \"load\", \"tiles\": %zu, \"points\": %zu, \"points_per_tile\": %.0f, \"repeats\": %d, "
      "\"read_ms_median\": %.1f, \"fold_ms_median\": %.1f, \"read_mpoints_per_s\": %.2f, "
      "\"fold_mpoints_per_s\": %.2f, \"load_mpoints_per_s\": %.2f, \"read_cpu_ms_median\": %.1f, "
      "\"fold_cpu_ms_median\": %.1f, \"load_mpoints_per_cpu_s\": %.2f, \"threads\": 1}\n",
      change.added.size(), points, static_cast<double>(points) / change.added.size(), repeats, read, fold,
      points / read / 1e3, points / fold / 1e3, points / (read + fold) / 1e3, read_cpu, fold_cpu,
      points / (read_cpu + fold_cpu) / 1e3);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const std::string cmd = argc > 1 ? argv[1] : "";
    if (cmd == "prepare" && argc == 7)
      return prepare(argv[2], std::atoi(argv[3]), argv[4], std::atof(argv[5]), std::atof(argv[6]));
    if (cmd == "run" && argc == 8)
      return run(argv[2], argv[3], std::atof(argv[4]), std::atoi(argv[5]), std::atoi(argv[6]), std::atof(argv[7]));
    if (cmd == "load" && argc == 5) return load(argv[2], std::atof(argv[3]), std::atoi(argv[4]));
    std::fprintf(stderr,
                 "usage: bench_scaling prepare BASE.pcd FACTOR DIR TILE_SIZE SECONDS\n"
                 "       bench_scaling run DIR global|tiles TILE_SIZE N K SECONDS\n"
                 "       bench_scaling load DIR TILE_SIZE REPEATS\n");
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_scaling: %s\n", e.what());
    return 1;
  }
}
