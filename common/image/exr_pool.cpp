#include "common/image/exr_pool.h"

#include <ImfThreading.h>

#include <algorithm>
#include <condition_variable>
#include <mutex>
#include <thread>

namespace raystack::image {
namespace {

std::mutex mu;
std::condition_variable changed;
int holders = 0;  // leases alive (under mu)
int size = -1;    // the pool's size they share (under mu)
int waiting = 0;  // leases waiting for another size (under mu)

}  // namespace

ExrPoolLease::ExrPoolLease(ExrThreads threads)
    : threads_(threads == ExrThreads::kAllCores
                   ? static_cast<int>(std::max(1u, std::thread::hardware_concurrency()))
                   : 0) {
  std::unique_lock lock(mu);
  if (holders > 0 && size != threads_) {
    ++waiting;
    changed.wait(lock, [&] { return holders == 0 || size == threads_; });
    --waiting;
  }
  if (holders == 0 && size != threads_) {
    // Its threads sleep between files; started here, they take this thread's priority.
    if (Imf::globalThreadCount() != threads_) Imf::setGlobalThreadCount(threads_);
    size = threads_;
  }
  ++holders;
}

ExrPoolLease::~ExrPoolLease() {
  std::lock_guard lock(mu);
  if (--holders == 0) changed.notify_all();
}

int ExrPoolLease::Waiting() {
  std::lock_guard lock(mu);
  return waiting;
}

}  // namespace raystack::image
