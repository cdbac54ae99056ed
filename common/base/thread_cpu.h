#pragma once
// CPU time the calling thread has used, from the kernel's per-thread clock: what a frame's
// threads cost, as opposed to how long they ran (on 2 cores, ray threads and loader threads
// share the CPU, and the stats report both so the split is visible).

#include <time.h>

namespace raystack {

inline double ThreadCpuSeconds() {
  timespec t{};
  if (clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t) != 0) return 0;
  return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_nsec) * 1e-9;
}

}  // namespace raystack
