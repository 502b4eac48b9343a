// global_localize --map MAP.pcd [--map ...] (--scan SCAN.pcd [search options] | --requests FILE): finds the scan's
// pose on the map by branch-and-bound search and NDT, prints one JSON object per search. Used by
// `gpm global-localize` (which picks the tile files) and by bench/bench_global_localization.py.
#include <cmath>
#include <ctime>
#include <fstream>
#include <iostream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "grid_puzzle_localization/global_localization.hpp"
#include "grid_puzzle_localization/pcd_reader.hpp"
#include "grid_puzzle_localization/preprocess.hpp"
#include "grid_puzzle_localization/rpy.hpp"
#include "option_values.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

const char* kUsage =
    "usage: global_localize --map MAP.pcd [--map MAP2.pcd ...] --scan SCAN.pcd [--center X Y] [--size S]\n"
    "                       [--yaw-center A] [--yaw-range A] [--threads N] [--plain] [--set NAME=V] [--map-voxel V]\n"
    "       global_localize --map MAP.pcd [...] --requests FILE [--threads N] [--plain] [--map-voxel V]\n"
    "       global_localize --print-config\n"
    "Finds the pose of SCAN (x y z PCD, base frame) on the map (x y z PCD files, map frame) and prints JSON:\n"
    "x y z [m], roll pitch yaw [rad] (R = Rz(yaw) Ry(pitch) Rx(roll)), score, runner_up_score, confidence, seconds.\n"
    "  --center       centre of the searched square [m] (default: centre of the map's structure)\n"
    "  --size         edge of the searched square [m] (default 40)\n"
    "  --yaw-center   [rad] (default 0); --yaw-range [rad] full width (default 2 pi = full circle)\n"
    "  --threads      OpenMP threads, 0 = all cores (default 0)\n"
    "  --plain        plain branch and bound (no adapted initial score S0), for comparison\n"
    "  --set NAME=V   a numeric field of GlobalLocalizationConfig (e.g. --set resolution=0.4), repeatable\n"
    "  --map-voxel    downsampling leaf of the map [m], 0 = off (default 0.1)\n"
    "  --requests     one search per line: SCAN.pcd CENTER_X CENTER_Y SIZE YAW_CENTER YAW_RANGE; one JSON line\n"
    "                 each, with the map loaded once\n"
    "  --print-config prints the search's defaults (max_range [m]: how far around the square the map is needed)\n"
    "Exit status: 0 found, 1 nothing acceptable (the reason is printed), 2 bad input.\n";

using gpl::tools::number;
using gpl::tools::UsageError;

struct Args {
  std::vector<std::string> maps;
  std::string scan, requests;
  bool has_center = false;
  gpl::GlobalSearchRequest request;
  gpl::GlobalLocalizationConfig config;
  double map_voxel = 0.1;
};

/// --set NAME=VALUE: one numeric field of GlobalLocalizationConfig.
void set(gpl::GlobalLocalizationConfig* c, const std::string& assignment) {
  const std::size_t eq = assignment.find('=');
  const std::string name = assignment.substr(0, eq);
  const double v = eq == std::string::npos ? 0.0 : number("--set " + name, assignment.substr(eq + 1));
  const std::pair<const char*, double*> reals[] = {{"resolution", &c->resolution},
                                                   {"ground_cell", &c->ground_cell},
                                                   {"band_overlap", &c->band_overlap},
                                                   {"max_range", &c->max_range},
                                                   {"blur_sigma", &c->blur_sigma},
                                                   {"yaw_step", &c->yaw_step},
                                                   {"min_score", &c->min_score},
                                                   {"max_runner_up_ratio", &c->max_runner_up_ratio},
                                                   {"runner_up_distance", &c->runner_up_distance},
                                                   {"runner_up_yaw", &c->runner_up_yaw},
                                                   {"same_pose_distance", &c->same_pose_distance},
                                                   {"same_pose_yaw", &c->same_pose_yaw},
                                                   {"min_inlier_fraction", &c->min_inlier_fraction},
                                                   {"max_refinement_shift", &c->max_refinement_shift},
                                                   {"ndt.resolution", &c->ndt.resolution},
                                                   {"ndt.transformation_epsilon", &c->ndt.transformation_epsilon},
                                                   {"ndt.step_size", &c->ndt.step_size},
                                                   {"ndt.max_step_size", &c->ndt.max_step_size}};
  const std::pair<const char*, int*> integers[] = {{"max_scan_points", &c->max_scan_points},
                                                   {"min_scan_points", &c->min_scan_points},
                                                   {"levels", &c->levels},
                                                   {"max_poses", &c->max_poses},
                                                   {"initial_descents", &c->initial_descents},
                                                   {"refine_candidates", &c->refine_candidates},
                                                   {"ndt.max_iterations", &c->ndt.max_iterations}};
  for (const auto& [key, field] : reals)
    if (eq != std::string::npos && name == key) {
      *field = v;
      return;
    }
  for (const auto& [key, field] : integers)
    if (eq != std::string::npos && name == key) {
      *field = static_cast<int>(v);
      return;
    }
  throw UsageError("--set expects NAME=VALUE with a numeric field of GlobalLocalizationConfig, got '" + assignment +
                   "'");
}

Args parse(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    const std::string opt = argv[i];
    auto value = [&](int k = 1) -> std::string {
      if (i + k >= argc) throw UsageError("option " + opt + " needs a value");
      return argv[i + k];
    };
    if (opt == "-h" || opt == "--help") {
      std::cout << kUsage;
      std::exit(0);
    } else if (opt == "--print-config") {
      std::cout << "{\"max_range\": " << a.config.max_range << ", \"resolution\": " << a.config.resolution
                << ", \"size\": " << a.request.size << "}" << std::endl;
      std::exit(0);
    } else if (opt == "--map") {
      a.maps.push_back(value());
      ++i;
    } else if (opt == "--scan") {
      a.scan = value();
      ++i;
    } else if (opt == "--requests") {
      a.requests = value();
      ++i;
    } else if (opt == "--center") {
      a.request.center_x = number(opt, value(1));
      a.request.center_y = number(opt, value(2));
      a.has_center = true;
      i += 2;
    } else if (opt == "--size") {
      a.request.size = number(opt, value());
      ++i;
    } else if (opt == "--yaw-center") {
      a.request.yaw_center = number(opt, value());
      ++i;
    } else if (opt == "--yaw-range") {
      a.request.yaw_range = number(opt, value());
      ++i;
    } else if (opt == "--threads") {
      a.config.threads = static_cast<int>(number(opt, value()));
      a.config.ndt.threads = a.config.threads;
      ++i;
    } else if (opt == "--plain") {
      a.config.adapted_initial_score = false;
    } else if (opt == "--set") {
      set(&a.config, value());
      ++i;
    } else if (opt == "--map-voxel") {
      a.map_voxel = number(opt, value());
      if (a.map_voxel < 0.0) throw UsageError("--map-voxel must be >= 0 m (0 disables downsampling)");
      ++i;
    } else {
      throw UsageError("unknown argument '" + opt + "'");
    }
  }
  if (a.maps.empty()) throw UsageError("give at least one --map MAP.pcd");
  if (a.scan.empty() == a.requests.empty()) throw UsageError("give either --scan SCAN.pcd or --requests FILE");
  const std::string problem = a.config.validate();
  if (!problem.empty()) throw UsageError(problem);
  return a;
}

/// One search as JSON; `cpu_seconds` is the process's CPU time of it (all threads), which a busy machine does not
/// inflate the way it inflates the wall time.
std::string json(const gpl::GlobalLocalizationResult& r, double cpu_seconds) {
  const gpl::XyzRpy pose = gpl::xyzRpyFromPose(r.map_T_base);  // fixed-axis roll-pitch-yaw (ROS convention)
  std::ostringstream js;
  js.precision(9);
  std::string reason;
  for (const char c : r.reason) reason += (c == '"' || c == '\\') ? std::string("\\") + c : std::string(1, c);
  js << "{\"found\": " << (r.found ? "true" : "false") << ", \"x\": " << pose(0) << ", \"y\": " << pose(1)
     << ", \"z\": " << pose(2) << ", \"roll\": " << pose(3) << ", \"pitch\": " << pose(4) << ", \"yaw\": " << pose(5)
     << ", \"score\": " << r.score << ", \"runner_up_score\": " << r.runner_up_score << ", \"fit\": " << r.fit
     << ", \"runner_up_fit\": " << r.runner_up_fit << ", \"confidence\": " << r.confidence
     << ", \"seconds\": " << r.seconds << ", \"grid_seconds\": " << r.grid_seconds
     << ", \"search_seconds\": " << r.search_seconds << ", \"refine_seconds\": " << r.refine_seconds
     << ", \"candidates_evaluated\": " << r.candidates_evaluated << ", \"search_resolution\": " << r.search_resolution
     << ", \"search_poses\": " << r.search_poses << ", \"local_poses\": " << r.local_poses
     << ", \"scan_points_used\": " << r.scan_points_used << ", \"cpu_seconds\": " << cpu_seconds
     << ", \"ndt_transformation_probability\": " << r.refinement.transformation_probability
     << ", \"ndt_inlier_fraction\": " << r.refinement.inlier_fraction
     << ", \"explained_fraction\": " << r.explained_fraction << ", \"ndt_status\": \""
     << gpl::toString(r.refinement.status) << "\", \"reason\": \"" << reason << "\"}";
  return js.str();
}

double cpuSince(std::clock_t start) { return static_cast<double>(std::clock() - start) / CLOCKS_PER_SEC; }

gpl::PointCloud finitePoints(const gpl::PointCloud& cloud, double voxel) {
  gpl::PointCloud out;
  for (const gpl::Point& p : cloud)
    if (p.allFinite() && !p.isZero()) out.push_back(p);
  return voxel > 0.0 ? gpl::voxelDownsample(out, voxel) : out;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    Args a = parse(argc, argv);
    gpl::PointCloud map;
    for (const std::string& path : a.maps) {
      const gpl::PointCloud part = gpl::readPcdXyz(path);
      map.insert(map.end(), part.begin(), part.end());
    }
    gpl::GlobalLocalizer localizer(a.config);
    localizer.setMap(finitePoints(map, a.map_voxel));
    if (!localizer.hasMap())
      throw std::runtime_error(
          "the map files hold no structure in the height bands above the ground: are they the "
          "right files?");
    if (!a.requests.empty()) {
      std::ifstream in(a.requests);
      if (!in) throw std::runtime_error("cannot read the requests file '" + a.requests + "'");
      std::string line;
      for (int n = 1; std::getline(in, line); ++n) {
        std::istringstream fields(line);
        std::string scan;
        gpl::GlobalSearchRequest q;
        if (!(fields >> scan >> q.center_x >> q.center_y >> q.size >> q.yaw_center >> q.yaw_range))
          throw std::runtime_error(a.requests + " line " + std::to_string(n) +
                                   ": expected SCAN.pcd CENTER_X CENTER_Y SIZE YAW_CENTER YAW_RANGE");
        const gpl::PointCloud points = gpl::readPcdXyz(scan);
        const std::clock_t cpu = std::clock();
        const gpl::GlobalLocalizationResult r = localizer.localize(points, q);
        std::cout << json(r, cpuSince(cpu)) << std::endl;
      }
      return 0;
    }
    if (!a.has_center) {
      const Eigen::Vector2d c = localizer.mapBounds().center();
      a.request.center_x = c.x();
      a.request.center_y = c.y();
    }
    const gpl::PointCloud points = gpl::readPcdXyz(a.scan);
    const std::clock_t cpu = std::clock();
    const gpl::GlobalLocalizationResult r = localizer.localize(points, a.request);
    std::cout << json(r, cpuSince(cpu)) << std::endl;
    if (!r.found) {
      std::cerr << "global_localize: no acceptable pose: " << r.reason << "\n";
      return 1;
    }
    return 0;
  } catch (const UsageError& e) {
    std::cerr << "global_localize: error: " << e.what() << "\n" << kUsage;
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "global_localize: error: " << e.what() << "\n";
    return 2;
  }
}
