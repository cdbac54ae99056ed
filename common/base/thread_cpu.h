#pragma once
// CPU time used by the calling thread or the whole process, from the kernel's clocks: what a
// frame's threads cost, as opposed to how long they ran (on 2 cores, ray threads and loader
// threads share the CPU, and the stats report both so the split is visible).

#include <time.h>

namespace raystack {

inline double CpuClockSeconds(clockid_t clock) {
  timespec t{};
  if (clock_gettime(clock, &t) != 0) return 0;
  return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_nsec) * 1e-9;
}

inline double ThreadCpuSeconds() { return CpuClockSeconds(CLOCK_THREAD_CPUTIME_ID); }
// Every thread of the process: with MPI's progress and the receiving thread, a slave's whole
// cost.
inline double ProcessCpuSeconds() { return CpuClockSeconds(CLOCK_PROCESS_CPUTIME_ID); }

}  // namespace raystack
