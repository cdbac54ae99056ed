#include "slave/block_loader.h"

#include <sys/resource.h>

#include <algorithm>
#include <bit>
#include <system_error>

#include "common/base/log.h"
#include "common/base/thread_cpu.h"
#include "common/base/thread_name.h"
#include "common/base/thread_policy.h"
#include "common/base/usable_cores.h"

namespace raystack::slave {
namespace {

// Times the calling thread has blocked (given up its CPU while waiting for something).
long VoluntarySwitches() {
  rusage usage{};
  getrusage(RUSAGE_THREAD, &usage);
  return usage.ru_nvcsw;
}

size_t Cores() { return static_cast<size_t>(UsableCores()); }

}  // namespace

std::unique_ptr<ReadBuffers> BufferShelf::Take() {
  std::lock_guard lock(mu_);
  if (kept_.empty()) return std::make_unique<ReadBuffers>();
  std::unique_ptr<ReadBuffers> b = std::move(kept_.back());
  kept_.pop_back();
  return b;
}

void BufferShelf::Put(std::unique_ptr<ReadBuffers> buffers) {
  std::lock_guard lock(mu_);
  kept_.push_back(std::move(buffers));
}

BlockLoader::BlockLoader(const store::StoreReader& store, BlockCache* cache, BlockSource* source,
                         LoaderOptions options, Deliver deliver, BufferShelf* shelf, Fail fail)
    : store_(store), cache_(cache), source_(source), options_(options),
      deliver_(std::move(deliver)), fail_(std::move(fail)), shelf_(shelf ? shelf : &own_shelf_),
      max_workers_(static_cast<size_t>(std::max(1, options.io_threads))),
      allowed_workers_(std::min<size_t>(max_workers_, Cores())),
      aio_(source->OpenAio(static_cast<int>(max_workers_))) {
  try {
    StartThreads();
  } catch (...) {  // a thread limit: the threads started are ended first (else std::terminate)
    {
      std::lock_guard lock(aio_mu_);
      aio_stop_ = true;
    }
    aio_cv_.notify_all();
    for (std::thread& w : workers_) w.join();
    throw;
  }
}

void BlockLoader::StartThreads() {
  if (aio_) {
    // Threads that wait for direct reads and decode them, as many as the cores: decoding is
    // CPU work, and one thread alone fell behind the disk (the ray threads idled 0.5 s of a
    // 0.7 s frame on dragon x36).
    aio_runs_.resize(max_workers_);
    for (size_t i = 0; i < std::min<size_t>(max_workers_, Cores()); ++i)
      workers_.emplace_back([this] {
        SetThreadName("rs-aio");
        SetBatchScheduling();
        Guarded(&BlockLoader::AioLoop);
        AddCpu(ThreadCpuSeconds());
      });
  }
  loader_ = std::thread([this] {
    SetThreadName("rs-loader");
    SetBatchScheduling();
    Guarded(&BlockLoader::LoaderLoop);
    AddCpu(ThreadCpuSeconds());
  });
}

void BlockLoader::Guarded(void (BlockLoader::*loop)()) {
  try {
    (this->*loop)();
  } catch (...) {  // nothing allocated here (status.h)
    if (fail_) fail_(Status::Error(kOutOfMemory));
  }
}

// Called by the loader thread only, so workers_ needs no lock (Stop joins the loader first).
bool BlockLoader::StartWorker() {
  try {
    workers_.emplace_back([this] {
      SetThreadName("rs-io");
      SetBatchScheduling();
      Guarded(&BlockLoader::WorkerLoop);
      AddCpu(ThreadCpuSeconds());
    });
    return true;
  } catch (...) {
    // A thread or address-space limit (ulimit -u, -v; std::thread's state may not be allocated
    // either): the loader goes on with the workers it has (the exception escaped the loader
    // thread: std::terminate), and tries no more (it tried again at each read that waited).
    std::lock_guard lock(runs_mu_);
    allowed_workers_ = workers_.size();
    threads_refused_ = true;
    LOG_WARNING("loader", "cannot start another I/O thread: going on with %zu", workers_.size());
    return false;
  }
}

BlockLoader::~BlockLoader() { Stop(); }

void BlockLoader::Stop() {
  {
    std::lock_guard lock(mu_);
    if (stop_) return;
    stop_ = true;
  }
  requests_cv_.notify_all();
  cache_->Shutdown();  // the loader may be waiting for room that will never be freed
  loader_.join();
  if (inline_buffers_) shelf_->Put(std::move(inline_buffers_));
  {
    std::lock_guard lock(runs_mu_);
    workers_stop_ = true;
  }
  runs_cv_.notify_all();
  {
    std::lock_guard lock(aio_mu_);
    aio_stop_ = true;
  }
  aio_cv_.notify_all();
  for (std::thread& w : workers_)
    if (w.joinable()) w.join();
}

void BlockLoader::Request(uint32_t block, uint32_t thread) {
  {
    std::lock_guard lock(mu_);
    requests_.push_back({block, thread});
  }
  requests_cv_.notify_one();
}

void BlockLoader::LoaderLoop() {
  std::vector<std::pair<uint32_t, uint32_t>> batch;
  std::vector<std::pair<uint32_t, uint64_t>> blocks;  // (block, threads)
  std::vector<Run> ready;                             // the batch's runs, to be read
  for (;;) {
    {
      std::unique_lock lock(mu_);
      requests_cv_.wait(lock, [&] { return stop_ || !requests_.empty(); });
      if (stop_) return;
      batch.swap(requests_);
      requests_.clear();
    }
    batches_.fetch_add(1, std::memory_order_relaxed);
    // Sorting by id sorts by file offset: blocks are written in id order.
    std::sort(batch.begin(), batch.end());
    blocks.clear();
    for (const auto& [block, thread] : batch) {
      if (blocks.empty() || blocks.back().first != block) blocks.push_back({block, 0});
      blocks.back().second |= uint64_t{1} << thread;
    }
    Run run;
    uint64_t run_bytes = 0;
    auto flush = [&] {
      if (!run.ids.empty()) ready.push_back(std::move(run));
      run = Run{};
      run_bytes = 0;
    };
    // A batch of a few runs (requests trickling in) the loader may read itself; a longer one
    // (a burst, or ray threads asking faster than one thread decodes) goes to the workers.
    auto submit = [&] {
      const bool few = ready.size() <= kInlineRunsAtMost;
      Submit(&ready, few);
      ready.clear();
    };
    for (const auto& [block, threads] : blocks) {
      {
        std::lock_guard lock(mu_);
        if (stop_) return;
        auto it = in_flight_.find(block);
        if (it != in_flight_.end()) {  // already being read: just add the askers
          it->second |= threads;
          continue;
        }
      }
      BlockCache::Claim claim = cache_->BeginLoad(block, /*wait=*/false);
      if (claim == BlockCache::Claim::kNoRoom) {
        flush();  // the reads already reserved must go first: they are what frees room
        submit();
        claim = cache_->BeginLoad(block);
      }
      if (claim == BlockCache::Claim::kFailed) {
        for (uint64_t t = threads; t; t &= t - 1)
          deliver_(static_cast<uint32_t>(std::countr_zero(t)), block,
                   cache_->FailureOf(block));
        continue;
      }
      if (claim != BlockCache::Claim::kLoad) {
        // Resident already (or being loaded by a synchronous reader): pin it for each asker;
        // one that loses a race with eviction asks again.
        std::lock_guard lock(mu_);
        for (uint64_t t = threads; t; t &= t - 1) {
          const uint32_t thread = static_cast<uint32_t>(std::countr_zero(t));
          if (claim == BlockCache::Claim::kResident && cache_->TryAcquire(block))
            deliver_(thread, block, OkStatus());
          else
            requests_.push_back({block, thread});
        }
        continue;
      }
      {
        std::lock_guard lock(mu_);
        in_flight_[block] = threads;
      }
      const store::BlockEntry& e = store_.blocks()[block];
      const bool adjacent = !run.ids.empty() && run.ids.back() + 1 == block;
      if (!adjacent || run_bytes + e.stored_bytes > options_.max_run_bytes) flush();
      run.ids.push_back(block);
      run_bytes += e.stored_bytes;
    }
    flush();
    submit();
  }
}

void BlockLoader::Submit(std::vector<Run>* runs, bool may_read_here) {
  runs_.fetch_add(runs->size(), std::memory_order_relaxed);
  if (aio_) {  // the whole batch at once: one system call, one notification of the disk
    {
      std::lock_guard lock(aio_mu_);
      for (Run& run : *runs) aio_queue_.push_back(std::move(run));
      StartQueuedAio();
    }
    aio_cv_.notify_one();
    return;
  }
  for (Run& run : *runs) Submit(std::move(run), may_read_here);
}

void BlockLoader::Submit(Run run, bool may_read_here) {
  if (read_inline_ && may_read_here) {
    ReadInline(run);
    return;
  }
  bool start;
  {
    std::lock_guard lock(runs_mu_);
    run_queue_.push_back(std::move(run));
    // Another worker only when every one is busy, and only as many as the cores until reads
    // have had to wait: reads served from the page cache are CPU work (copy, decode) that more
    // threads than cores only share worse with the ray threads (the first frame of 8 slaves
    // at 20% of a core each: 2 workers instead of 32, 1.11 -> 0.96 s, medians of 4 pairs); a
    // disk or a network needs many reads in flight, up to io_threads.
    start = run_queue_.size() > idle_workers_ && workers_.size() < allowed_workers_;
  }
  if (start && StartWorker()) return;  // the new worker takes it
  if (!workers_.empty()) {
    runs_cv_.notify_one();
  } else {
    // No worker to take the queue (none could be started): the loader reads it itself.
    for (;;) {
      Run queued;
      {
        std::lock_guard lock(runs_mu_);
        if (run_queue_.empty()) break;
        queued = std::move(run_queue_.front());
        run_queue_.pop_front();
      }
      ReadInline(queued);
    }
  }
}

bool BlockLoader::ReadAndComplete(const Run& run, std::vector<uint8_t>* bytes,
                                  store::AlignedBuffer* scratch) {
  BusyBegin();
  const long waits_before = VoluntarySwitches();
  const Status read = source_->ReadRun(run.ids, bytes);
  // The thread gave up its CPU during the read: it waited for the disk, a peer or an injected
  // latency, not for a copy from the page cache (preemption is an involuntary switch). Each
  // such read allows one more worker, so a rare wait on a lock in a page-cache read adds one,
  // and a disk, where every read waits, soon has them all.
  const bool waited = VoluntarySwitches() != waits_before;
  if (waited) {
    std::lock_guard lock(runs_mu_);
    if (!threads_refused_) allowed_workers_ = std::min(max_workers_, allowed_workers_ + 1);
  }
  CompleteRun(run, read, bytes->data(), scratch);
  BusyEnd();
  return waited;
}

void BlockLoader::ReadInline(const Run& run) {
  ++inline_runs_;
  // Reads have to wait once two in a row gave up the CPU. One alone is not enough: a read from
  // the page cache now and then does too (8 slaves: in about one frame of two, some slave's
  // loader met one among its first few dozen reads).
  if (!inline_buffers_) inline_buffers_ = shelf_->Take();
  const bool waited = ReadAndComplete(run, &inline_buffers_->bytes, &inline_buffers_->scratch);
  waited_in_a_row_ = waited ? waited_in_a_row_ + 1 : 0;
  if (waited_in_a_row_ == 2) read_inline_ = false;
}

void BlockLoader::WorkerLoop() {
  std::unique_ptr<ReadBuffers> buffers = shelf_->Take();
  for (;;) {
    Run run;
    {
      std::unique_lock lock(runs_mu_);
      ++idle_workers_;
      runs_cv_.wait(lock, [&] { return !run_queue_.empty() || workers_stop_; });
      --idle_workers_;
      if (run_queue_.empty()) break;
      run = std::move(run_queue_.front());
      run_queue_.pop_front();
    }
    ReadAndComplete(run, &buffers->bytes, &buffers->scratch);
  }
  shelf_->Put(std::move(buffers));
}

void BlockLoader::StartQueuedAio() {
  // Runs start half the depth at a time while at least half the depth is in flight: each
  // io_submit costs the disk one notification (a guest exit in a VM, and the block layer's
  // plug and dispatch), and reads come back a few at a time. Restarting the slots freed by
  // every few reads took 2,450-2,510 calls for 10,850 reads on dragon x36; in halves, 660-710
  // (stack 0.95 -> 0.82 s, loader CPU -20%, 8 interleaved pairs; tools/bench/RESULTS.md).
  // Half the depth in flight still keeps the disk busy (16 reads of ~24 KB in flight: over
  // 3x the stack's read rate on this VM's disk).
  const size_t in_flight = static_cast<size_t>(aio_->in_flight());
  const size_t half = std::max<size_t>(1, max_workers_ / 2);
  if (in_flight >= half && (max_workers_ - in_flight < half || aio_queue_.size() < half)) return;
  while (!aio_queue_.empty()) {
    const int slot = aio_->Prepare(aio_queue_.front().ids);
    if (slot < 0) break;  // every slot in flight: the AIO threads start the rest as reads end
    BusyBegin();
    aio_runs_[slot] = std::move(aio_queue_.front());
    aio_queue_.pop_front();
  }
  aio_->SubmitPrepared();  // the batch's runs in one system call
}

void BlockLoader::AioLoop() {
  std::vector<AioRuns::Finished> finished;
  std::unique_ptr<ReadBuffers> buffers = shelf_->Take();  // its scratch
  for (;;) {
    {
      std::unique_lock lock(aio_mu_);
      aio_cv_.wait(lock, [&] { return aio_stop_ || aio_->in_flight() > 0; });
      // Runs wait in the queue only while half the slots or more are taken (StartQueuedAio),
      // so nothing in flight means nothing left.
      if (aio_->in_flight() == 0) break;
    }
    // A few reads at a time, so the other threads share the decoding of a burst. The
    // timeout only matters when another thread took the last reads in flight.
    finished.clear();
    aio_->Wait(/*timeout_ms=*/20, /*max=*/4, &finished);
    for (AioRuns::Finished& f : finished) {
      Run run;
      {
        std::lock_guard lock(aio_mu_);
        run = std::move(aio_runs_[f.slot]);
      }
      CompleteRun(run, f.status, f.bytes.data(), &buffers->scratch);
      aio_->Release(f.slot);
      BusyEnd();
    }
    // The runs waiting for the slots just freed start together, in one system call: started
    // one per freed slot, every read cost the disk its own notification (dragon x36: 9,100
    // io_submit calls for 10,700 reads, against 2,500; the frame 0.96-1.14 -> 0.85-0.95 s).
    {
      std::lock_guard lock(aio_mu_);
      StartQueuedAio();
    }
    aio_cv_.notify_one();  // a thread that found nothing in flight shares these reads
  }
}

void BlockLoader::CompleteRun(const Run& run, const Status& read, const uint8_t* bytes,
                              store::AlignedBuffer* scratch) {
  const uint64_t base = store_.blocks()[run.ids.front()].offset;
  for (uint32_t id : run.ids) {
    const store::BlockEntry& e = store_.blocks()[id];
    std::span<const uint8_t> stored;
    if (read.ok()) stored = std::span<const uint8_t>(bytes + (e.offset - base), e.stored_bytes);
    Complete(id, read, stored, scratch);
  }
}

void BlockLoader::Complete(uint32_t block, const Status& read, std::span<const uint8_t> stored,
                           store::AlignedBuffer* scratch) {
  // The block stays in flight while it decodes, so a thread that asks for it meanwhile is
  // added to its askers. (Taken out before, such a request found the block loading in the
  // cache and went back to the loader's queue, which the loader then turned over without
  // sleeping until the decode ended: 401,006 loader batches for 10,752 reads on dragon x36.)
  uint64_t threads;
  {
    std::lock_guard lock(mu_);
    threads = in_flight_[block];
  }
  Status status = read;
  if (read.ok()) {
    status = cache_->FinishLoad(block, stored, std::popcount(threads), scratch);
  } else {
    cache_->FailLoad(block, read);
  }
  uint64_t late;
  bool asked_again = false;
  {
    std::lock_guard lock(mu_);
    late = in_flight_[block] & ~threads;
    in_flight_.erase(block);
    // Late askers get their pins now, before any asker is told and could release its own:
    // until then the block cannot be evicted, so this cannot fail (if it ever did, the ask
    // goes back to the loader like any other).
    for (uint64_t t = late; t && status.ok(); t &= t - 1) {
      const auto thread = static_cast<uint32_t>(std::countr_zero(t));
      if (cache_->TryAcquire(block) == nullptr) {
        late &= ~(uint64_t{1} << thread);
        requests_.push_back({block, thread});
        asked_again = true;
      }
    }
  }
  if (asked_again) requests_cv_.notify_one();
  for (uint64_t t = threads | late; t; t &= t - 1)
    deliver_(static_cast<uint32_t>(std::countr_zero(t)), block, status);
}

void BlockLoader::AddCpu(double seconds) {
  std::lock_guard lock(busy_mu_);
  cpu_seconds_ += seconds;
}

double BlockLoader::cpu_seconds() const {
  std::lock_guard lock(busy_mu_);
  return cpu_seconds_;
}

void BlockLoader::BusyBegin() {
  std::lock_guard lock(busy_mu_);
  if (active_++ == 0) busy_since_ = std::chrono::steady_clock::now();
}

void BlockLoader::BusyEnd() {
  std::lock_guard lock(busy_mu_);
  if (--active_ == 0)
    busy_seconds_ +=
        std::chrono::duration<double>(std::chrono::steady_clock::now() - busy_since_).count();
}

double BlockLoader::busy_seconds() const {
  std::lock_guard lock(busy_mu_);
  double s = busy_seconds_;
  if (active_ > 0)
    s += std::chrono::duration<double>(std::chrono::steady_clock::now() - busy_since_).count();
  return s;
}

}  // namespace raystack::slave
