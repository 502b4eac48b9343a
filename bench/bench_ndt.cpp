// NDT benchmark: our matcher (each search method, 1 and 2 threads) and PCL 1.13's NDT on the real HDL-32E pair,
// plus the incremental target update. Prints one JSON object per line. Usage: bench_ndt [ours|pcl|incremental|--quick]
// (--quick: one configuration of each, one repeat: checks that it runs).
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/registration/ndt.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <fstream>
#include <iostream>
#include <sstream>
#include <thread>

#include "grid_puzzle_localization/ndt.hpp"
#include "ndt_real_pair.hpp"
#include "ndt_synthetic.hpp"

namespace gpl = grid_puzzle_localization;
using Clock = std::chrono::steady_clock;

namespace {

int g_repeats = 15;  // warm aligns per configuration (median reported); 1 with --quick

double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

std::string cpuModel() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
  return "unknown";
}

std::string hardware() {
  std::ostringstream o;
  const std::time_t now = std::time(nullptr);
  char stamp[32];
  std::strftime(stamp, sizeof(stamp), "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&now));
  double load = 0.0;
  std::ifstream("/proc/loadavg") >> load;
  o << "\"cpu\": \"" << cpuModel() << "\", \"cores\": " << std::thread::hardware_concurrency() << ", \"utc\": \""
    << stamp << "\", \"loadavg_1min\": " << load;
  return o.str();
}

// Process CPU time [ms] (all threads): unlike wall time it barely depends on what else the machine runs.
double cpuMs() { return 1000.0 * static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

void printLine(const std::string& impl, const std::string& method, int threads, double warm, double cpu, double cold,
               int iterations, const Eigen::Matrix4d& T, double build_ms, double bytes_per_voxel, bool converged) {
  const auto [te, re] = gpl::synthetic::poseError(gpl::real_pair::reference(), T);
  std::cout << "{\"bench\": \"ndt_align\", \"impl\": \"" << impl << "\", \"method\": \"" << method
            << "\", \"threads\": " << threads << ", \"warm_ms\": " << warm << ", \"cpu_ms\": " << cpu
            << ", \"cold_ms\": " << cold << ", \"iterations\": " << iterations
            << ", \"converged\": " << (converged ? "true" : "false") << ", \"translation_error_m\": " << te
            << ", \"rotation_error_deg\": " << re << ", \"target_build_ms\": " << build_ms
            << ", \"bytes_per_voxel\": " << bytes_per_voxel << ", " << hardware() << "}" << std::endl;
}

void benchOurs(const gpl::PointCloud& target, const gpl::PointCloud& source, gpl::NdtSearchMethod method, int threads) {
  gpl::NdtConfig cfg;
  cfg.search = method;
  cfg.threads = threads;
  const gpl::NdtAligner aligner(cfg);
  const Eigen::Matrix4f guess = Eigen::Matrix4f::Identity();
  auto t0 = Clock::now();
  gpl::NdtTarget ndt_target(cfg);
  ndt_target.setTarget(target);
  const auto map = ndt_target.snapshot();
  gpl::NdtResult r = aligner.align(*map, source, guess);
  const double cold = msSince(t0);
  std::vector<double> builds, times, cpu;
  for (int i = 0; i < g_repeats; ++i) {
    t0 = Clock::now();
    gpl::NdtTarget rebuilt(cfg);
    rebuilt.setTarget(target);
    builds.push_back(msSince(t0));
    const double c0 = cpuMs();
    t0 = Clock::now();
    r = aligner.align(*map, source, guess);
    times.push_back(msSince(t0));
    cpu.push_back(cpuMs() - c0);
  }
  printLine("ours", gpl::toString(method), threads, median(times), median(cpu), cold, r.iterations,
            r.transform.cast<double>(), median(builds), map->bytesPerVoxel(), r.converged);
}

void benchPcl(const gpl::PointCloud& target, const gpl::PointCloud& source) {
  auto toPcl = [](const gpl::PointCloud& c) {
    pcl::PointCloud<pcl::PointXYZ>::Ptr out(new pcl::PointCloud<pcl::PointXYZ>);
    out->reserve(c.size());
    for (const auto& p : c) out->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
    return out;
  };
  const auto tgt = toPcl(target), src = toPcl(source);
  const gpl::NdtConfig defaults;
  auto make = [&] {
    pcl::NormalDistributionsTransform<pcl::PointXYZ, pcl::PointXYZ> ndt;
    ndt.setResolution(static_cast<float>(defaults.resolution));
    ndt.setStepSize(defaults.step_size);
    ndt.setTransformationEpsilon(1e-4);  // PCL's default stops after one iteration on this pair
    ndt.setMaximumIterations(defaults.max_iterations);
    ndt.setOulierRatio(defaults.outlier_ratio);  // sic: PCL 1.13 spells it so
    return ndt;
  };
  pcl::PointCloud<pcl::PointXYZ> out;
  auto t0 = Clock::now();
  auto ndt = make();
  ndt.setInputTarget(tgt);
  const double build_ms = msSince(t0);
  ndt.setInputSource(src);
  ndt.align(out, Eigen::Matrix4f::Identity());
  const double cold = msSince(t0);
  std::vector<double> times, cpu;
  for (int i = 0; i < g_repeats; ++i) {
    const double c0 = cpuMs();
    t0 = Clock::now();
    ndt.align(out, Eigen::Matrix4f::Identity());
    times.push_back(msSince(t0));
    cpu.push_back(cpuMs() - c0);
  }
  printLine("pcl-1.13", "RADIUS(kdtree)", 1, median(times), median(cpu), cold, ndt.getFinalNumIteration(),
            ndt.getFinalTransformation().cast<double>(), build_ms, 0.0, ndt.hasConverged());
}

// Add and remove one 2 m x 2 m tile against a 100 m x 100 m target, versus rebuilding the whole target; with the
// coarse map kept up (the default coarse_map_factor) or without one (0).
void benchIncremental(int threads, int coarse_map_factor) {
  gpl::NdtConfig cfg;
  cfg.threads = threads;
  cfg.coarse_map_factor = coarse_map_factor;
  const gpl::PointCloud world = gpl::synthetic::scene(3, 0.02, 1000000, 50.0);
  gpl::PointCloud tile;
  for (const auto& p : gpl::synthetic::scene(4, 0.02, 1000000, 50.0))
    if (p.x() >= 10.0f && p.x() < 12.0f && p.y() >= 10.0f && p.y() < 12.0f) tile.push_back(p);
  gpl::NdtTarget target(cfg);
  std::vector<double> full, add, remove;
  for (int i = 0; i < 5; ++i) {
    const auto t0 = Clock::now();
    target.setTarget(world);
    full.push_back(msSince(t0));
  }
  for (int i = 0; i < g_repeats; ++i) {
    auto t0 = Clock::now();
    target.addTarget(1, tile);
    add.push_back(msSince(t0));
    t0 = Clock::now();
    target.removeTarget(1);
    remove.push_back(msSince(t0));
  }
  const auto map = target.snapshot();
  std::cout << "{\"bench\": \"ndt_incremental\", \"threads\": " << threads
            << ", \"coarse_map_factor\": " << coarse_map_factor << ", \"target_points\": " << world.size()
            << ", \"target_voxels\": " << map->voxelCount() << ", \"tile_points\": " << tile.size()
            << ", \"add_tile_ms\": " << median(add) << ", \"remove_tile_ms\": " << median(remove)
            << ", \"full_rebuild_ms\": " << median(full) << ", \"bytes_per_voxel\": " << map->bytesPerVoxel() << ", "
            << hardware() << "}" << std::endl;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string only = argc > 1 ? argv[1] : "";
  const bool quick = only == "--quick";
  if (quick) g_repeats = 1;
  const gpl::PointCloud target = gpl::real_pair::target();
  const gpl::PointCloud source = gpl::real_pair::source();
  if (quick) {
    benchOurs(target, source, gpl::NdtSearchMethod::DIRECT7, 1);
    benchPcl(target, source);
    benchIncremental(1, gpl::NdtConfig().coarse_map_factor);
    return 0;
  }
  if (only.empty() || only == "ours")
    for (const auto m : {gpl::NdtSearchMethod::DIRECT1, gpl::NdtSearchMethod::DIRECT7, gpl::NdtSearchMethod::DIRECT27,
                         gpl::NdtSearchMethod::RADIUS})
      for (const int threads : {1, 2}) benchOurs(target, source, m, threads);
  if (only.empty() || only == "pcl") benchPcl(target, source);
  if (only.empty() || only == "incremental")
    for (const int threads : {1, 2})
      for (const int factor : {0, gpl::NdtConfig().coarse_map_factor}) benchIncremental(threads, factor);
  return 0;
}
