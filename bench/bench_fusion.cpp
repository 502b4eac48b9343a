// Per-scan cost of the sliding-window update (Ceres solve plus marginalization) on a closed-form drive at 10 Hz
// with 200 Hz MEMS-like IMU samples and 5 cm / 0.3 deg NDT stand-in measurements. Prints one JSON line: wall-clock
// percentiles of SlidingWindow::addScan after the window filled (and its thread CPU time, which other
// tenants of the cores do not inflate), the solve and marginalization shares, Ceres
// iterations, and the position error against the closed form. No ROS.
//
// Usage: bench_fusion [--scans N] [--max-states N_a] [--max-iterations N]
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "grid_puzzle_localization/fusion/sliding_window.hpp"
#include "imu_drive.hpp"

namespace gpl = grid_puzzle_localization;
namespace drive = grid_puzzle_localization::imu_drive;

namespace {

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(std::min<double>(v.size() - 1, std::floor(q * (v.size() - 1) + 0.5)))];
}

double threadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

}  // namespace

int main(int argc, char** argv) {
  int scans = 3000;  // 5 minutes, 2.4 km
  gpl::SlidingWindowConfig config;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (std::strcmp(argv[i], "--scans") == 0) {
      scans = std::stoi(argv[i + 1]);
    } else if (std::strcmp(argv[i], "--max-states") == 0) {
      config.max_states = std::stoi(argv[i + 1]);
    } else if (std::strcmp(argv[i], "--max-iterations") == 0) {
      config.max_iterations = std::stoi(argv[i + 1]);
    } else {
      std::fprintf(stderr, "bench_fusion: unknown option %s (use --scans N, --max-states N, --max-iterations N)\n",
                   argv[i]);
      return 2;
    }
  }
  gpl::SlidingWindow window(config);
  std::mt19937 imu_rng(7), ndt_rng(11);
  const double sp = 0.05, sr = 0.005;
  std::vector<double> total_ms, cpu_ms, solve_ms, marg_ms, iterations;
  double sq_error = 0.0;
  int next_imu = 0;
  for (int k = 0; k < scans; ++k) {
    const double stamp = k / drive::kScanRate;
    for (; next_imu / drive::kImuRate <= stamp + 1e-9; ++next_imu)
      window.addImu(drive::imuSample(drive::drive, next_imu / drive::kImuRate, drive::mems(), imu_rng));
    const Eigen::Isometry3d m = drive::noisyPose(drive::drive(stamp).pose, sp, sr, ndt_rng);
    const auto t0 = std::chrono::steady_clock::now();
    const double cpu0 = threadCpuMs();
    const auto est = window.addScan(stamp, &m, drive::information(sp, sr));
    const double cpu = threadCpuMs() - cpu0;
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    window.takeWarnings();
    if (k < config.max_states) continue;  // the window is still filling
    total_ms.push_back(ms);
    cpu_ms.push_back(cpu);
    solve_ms.push_back(window.lastReport().solve_ms);
    marg_ms.push_back(window.lastReport().marginalize_ms);
    iterations.push_back(window.lastReport().iterations);
    sq_error += (est->pose.translation() - drive::drive(stamp).pose.translation()).squaredNorm();
  }
  const double n = static_cast<double>(total_ms.size());
  std::printf(
      "{\"bench\": \"fusion_window_update\", \"scans\": %zu, \"max_states\": %d, \"threads\": 1, "
      "\"update_ms\": {\"p50\": %.3f, \"p95\": %.3f, \"p99\": %.3f, \"max\": %.3f}, "
      "\"update_thread_cpu_ms\": {\"p50\": %.3f, \"p95\": %.3f}, "
      "\"solve_ms\": {\"p50\": %.3f, \"p95\": %.3f}, \"marginalize_ms\": {\"p50\": %.3f, \"p95\": %.3f}, "
      "\"ceres_iterations_p50\": %.0f, \"position_rmse_m\": %.4f, \"ndt_stand_in_std_m\": %.3f}\n",
      total_ms.size(), config.max_states, percentile(total_ms, 0.5), percentile(total_ms, 0.95),
      percentile(total_ms, 0.99), percentile(total_ms, 1.0), percentile(cpu_ms, 0.5), percentile(cpu_ms, 0.95),
      percentile(solve_ms, 0.5), percentile(solve_ms, 0.95), percentile(marg_ms, 0.5), percentile(marg_ms, 0.95),
      percentile(iterations, 0.5), std::sqrt(sq_error / n), sp);
  return 0;
}
