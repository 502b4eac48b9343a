// ndt_align TARGET.pcd SOURCE.pcd [options]: aligns two PCD files with the core NDT and prints one JSON object.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "grid_puzzle_localization/ndt.hpp"
#include "grid_puzzle_localization/pcd_reader.hpp"
#include "grid_puzzle_localization/preprocess.hpp"
#include "grid_puzzle_localization/rpy.hpp"
#include "option_values.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

const char* kUsage =
    "usage: ndt_align TARGET.pcd SOURCE.pcd [--method DIRECT1|DIRECT7|DIRECT27|RADIUS] [--threads N]\n"
    "                 [--resolution R] [--voxel V] [--max-iterations N] [--epsilon E] [--step-size S]\n"
    "                 [--max-step-size M] [--guess x y z roll pitch yaw]\n"
    "Aligns SOURCE to TARGET (both x y z PCD files), prints T_target_source (4x4 and as\n"
    "pose [x y z roll pitch yaw], ROS convention) and diagnostics as JSON.\n"
    "  --method      neighbour search (default DIRECT7)\n"
    "  --threads     OpenMP threads, 0 = all cores (default 0)\n"
    "  --resolution  NDT voxel size [m] (default 1.0)\n"
    "  --voxel       downsampling leaf [m] for both clouds after dropping (0,0,0) points; 0 = off (default 0.1)\n"
    "  --guess       initial T_target_source: metres and radians, ROS's fixed-axis roll pitch yaw,\n"
    "                T = t * Rz(yaw) * Ry(pitch) * Rx(roll)\n";

using gpl::tools::integer;
using gpl::tools::number;
using gpl::tools::UsageError;

struct Args {
  std::string target, source;
  gpl::NdtConfig config;
  double voxel = 0.1;
  gpl::XyzRpy guess = gpl::XyzRpy::Zero();
};

Args parse(int argc, char** argv) {
  Args a;
  std::vector<std::string> positional;
  for (int i = 1; i < argc; ++i) {
    const std::string opt = argv[i];
    auto value = [&](int k = 1) -> std::string {
      if (i + k >= argc) throw UsageError("option " + opt + " needs a value");
      return argv[i + k];
    };
    if (opt == "-h" || opt == "--help") {
      std::cout << kUsage;
      std::exit(0);
    } else if (opt == "--method") {
      if (!gpl::parseSearchMethod(value(), &a.config.search))
        throw UsageError("unknown --method '" + value() + "'; use DIRECT1, DIRECT7, DIRECT27 or RADIUS");
      ++i;
    } else if (opt == "--threads") {
      a.config.threads = integer(opt, value());
      ++i;
    } else if (opt == "--resolution") {
      a.config.resolution = number(opt, value());
      ++i;
    } else if (opt == "--voxel") {
      a.voxel = number(opt, value());
      if (a.voxel < 0.0) throw UsageError("--voxel must be >= 0 m (0 disables downsampling)");
      ++i;
    } else if (opt == "--max-iterations") {
      a.config.max_iterations = integer(opt, value());
      ++i;
    } else if (opt == "--epsilon") {
      a.config.transformation_epsilon = number(opt, value());
      ++i;
    } else if (opt == "--step-size") {
      a.config.step_size = number(opt, value());
      ++i;
    } else if (opt == "--max-step-size") {
      a.config.max_step_size = number(opt, value());
      ++i;
    } else if (opt == "--guess") {
      for (int k = 0; k < 6; ++k) a.guess(k) = number(opt, value(k + 1));
      i += 6;
    } else if (opt.size() > 1 && opt[0] == '-' && !std::isdigit(static_cast<unsigned char>(opt[1]))) {
      throw UsageError("unknown option '" + opt + "'");
    } else {
      positional.push_back(opt);
    }
  }
  if (positional.size() != 2) throw UsageError("expected TARGET.pcd and SOURCE.pcd");
  a.target = positional[0];
  a.source = positional[1];
  const std::string problem = a.config.validate();
  if (!problem.empty()) throw UsageError(problem);
  return a;
}

gpl::PointCloud load(const std::string& path, double voxel) {
  gpl::PreprocessConfig pre;
  pre.min_range = 0.0;
  pre.max_range = std::numeric_limits<double>::max();
  pre.voxel_size = voxel;
  return gpl::preprocess(gpl::readPcdXyz(path), pre);
}

double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int main(int argc, char** argv) {
  try {
    const Args a = parse(argc, argv);
    const gpl::PointCloud target = load(a.target, a.voxel);
    const gpl::PointCloud source = load(a.source, a.voxel);
    auto t0 = std::chrono::steady_clock::now();
    gpl::NdtTarget ndt_target(a.config);
    ndt_target.setTarget(target);
    const auto snapshot = ndt_target.snapshot();
    const double build_ms = msSince(t0);
    const gpl::NdtAligner aligner(a.config);
    t0 = std::chrono::steady_clock::now();
    const gpl::NdtResult r = aligner.align(*snapshot, source, gpl::poseFromXyzRpy(a.guess).cast<float>());
    const double align_ms = msSince(t0);
    std::ostringstream js;
    js.precision(9);
    js << "{\"transform\": [";
    for (int i = 0; i < 4; ++i) {
      js << (i ? ", [" : "[");
      for (int j = 0; j < 4; ++j) js << (j ? ", " : "") << r.transform(i, j);
      js << "]";
    }
    const gpl::XyzRpy pose = gpl::xyzRpyFromPose(Eigen::Isometry3d(r.transform.cast<double>()));
    js << "], \"pose\": [";
    for (int i = 0; i < 6; ++i) js << (i ? ", " : "") << pose(i);
    js << "], \"iterations\": " << r.iterations << ", \"converged\": " << (r.converged ? "true" : "false")
       << ", \"status\": \"" << gpl::toString(r.status) << "\", \"score\": " << r.score
       << ", \"transformation_probability\": " << r.transformation_probability << ", \"nvtl\": " << r.nvtl
       << ", \"inlier_fraction\": " << r.inlier_fraction << ", \"time_ms\": " << align_ms
       << ", \"target_build_ms\": " << build_ms << ", \"target_points\": " << target.size()
       << ", \"source_points\": " << r.source_points << ", \"target_voxels\": " << snapshot->gaussianCount()
       << ", \"method\": \"" << gpl::toString(a.config.search) << "\", \"threads\": " << a.config.threads
       << ", \"resolution\": " << a.config.resolution << "}";
    std::cout << js.str() << std::endl;
    if (r.status != gpl::NdtResultStatus::OK && r.status != gpl::NdtResultStatus::MAX_ITERATIONS) {
      std::cerr << "ndt_align: alignment failed (" << gpl::toString(r.status) << "): " << r.message << "\n";
      return 1;
    }
    return 0;
  } catch (const UsageError& e) {
    std::cerr << "ndt_align: error: " << e.what() << "\n" << kUsage;
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "ndt_align: error: " << e.what() << "\n";
    return 2;
  }
}
