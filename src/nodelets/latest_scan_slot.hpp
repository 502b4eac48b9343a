// A slot of one for scans waiting for the scan thread: a newer scan replaces one not yet taken, and the
// replaced ones are counted, so a slow localizer skips scans (and says how many) instead of falling behind.
#pragma once

#include <cstdint>
#include <mutex>
#include <utility>

namespace grid_puzzle_localization {

/// `Ptr` is a shared pointer to a scan (sensor_msgs::PointCloud2::ConstPtr in the nodelet); an empty Ptr
/// means "no scan". Thread-safe: scans are put by one thread and taken by another.
template <class Ptr>
class LatestScanSlot {
 public:
  /// Keeps `scan` as the one to take next; a scan still waiting is dropped and counted.
  void put(Ptr scan) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (waiting_) ++dropped_;
    waiting_ = std::move(scan);
  }

  /// The waiting scan, leaving the slot empty; empty when there is none (a newer put's take got it).
  Ptr take() {
    Ptr scan;
    std::lock_guard<std::mutex> lock(mutex_);
    scan.swap(waiting_);
    return scan;
  }

  /// Scans replaced in the slot before they were taken, since construction.
  std::uint64_t dropped() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return dropped_;
  }

 private:
  mutable std::mutex mutex_;
  Ptr waiting_;
  std::uint64_t dropped_ = 0;
};

}  // namespace grid_puzzle_localization
