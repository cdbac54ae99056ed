#pragma once
// Scheduling for threads that serve others' work in the background (a block loader's threads).
//
// SCHED_BATCH: a thread woken (a read done, a request posted) does not preempt the thread
// running on the CPU; it runs when that one's time slice ends or it blocks. A ray thread that
// has rays in other queues keeps tracing instead of being switched out for each of the ~14,000
// blocks of a frame, and the loader's threads run in longer stretches. In a PVM guest each
// switch and reschedule interrupt leaves the guest: the dragon x36 out-of-core frame went from
// 1.12-1.22 s to 0.91-1.05 s (tools/bench/RESULTS.md). A ray thread with nothing to trace
// blocks, and the loader runs at once: loads are only late where there is other work to do.
// Same nice level, so the same share of the CPU over time.

#include <pthread.h>
#include <sched.h>

namespace raystack {

// For the calling thread. Best effort: where the system refuses, the thread stays as it was.
inline void SetBatchScheduling() {
  sched_param param{};
  param.sched_priority = 0;
  pthread_setschedparam(pthread_self(), SCHED_BATCH, &param);
}

}  // namespace raystack
