// Private helper of the core: background threads (the map worker, a start search) run nicer than the scan thread, so
// on a loaded machine matching the scans comes first. Linux keeps niceness per thread, and threads started from such
// a thread (its OpenMP team) inherit it.
#pragma once

#if defined(__linux__)
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <cerrno>
#endif
#include <algorithm>

namespace grid_puzzle_localization {

/// Raises the calling thread's niceness by `increment` (at most to 19). Best effort: raising one's own niceness needs
/// no privilege, and a failure only leaves the thread as it was.
inline void lowerCallingThreadPriority(int increment) {
#if defined(__linux__)
  const auto tid = static_cast<id_t>(syscall(SYS_gettid));
  errno = 0;
  const int nice = getpriority(PRIO_PROCESS, tid);
  if (errno == 0) static_cast<void>(setpriority(PRIO_PROCESS, tid, std::min(19, nice + increment)));
#else
  (void)increment;
#endif
}

}  // namespace grid_puzzle_localization
