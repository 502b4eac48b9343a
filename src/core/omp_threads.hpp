// Private helper of the core: the OpenMP team size for a "threads" parameter (0 = all cores). Without OpenMP (the
// ThreadSanitizer build, since libgomp is not instrumented) everything runs on the calling thread.
#pragma once

#ifdef _OPENMP
#include <omp.h>
#endif

namespace grid_puzzle_localization {

inline int resolveThreads(int threads) {
#ifdef _OPENMP
  return threads > 0 ? threads : omp_get_max_threads();
#else
  (void)threads;
  return 1;
#endif
}

/// Index of the calling thread in the current team.
inline int teamThreadNum() {
#ifdef _OPENMP
  return omp_get_thread_num();
#else
  return 0;
#endif
}

}  // namespace grid_puzzle_localization
