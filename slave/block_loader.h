#pragma once
// The loader (thesis Fig. VI.3's loading thread): ray threads request blocks they are missing;
// the loader takes all pending requests as one batch, sorts it by file offset, merges blocks
// that are neighbours on disk into one read and reserves their room in the cache.
//
// Until reads have to wait, the loader reads and decodes a batch of a few runs itself: a block
// from the page cache is CPU work, and handing it to another thread added two thread switches
// to it (one process, uncapped: 66 -> 48 us of CPU a block). Longer batches, and every run once
// reads wait (a disk, a peer, an injected latency), go to its I/O workers, so several decode at
// once and up to 32 reads are in flight (a disk, and even more a network filesystem, is
// fastest with a deep queue); workers start as reads pile up.
// Direct reads of a disk (--direct-io) need no thread each: the loader starts them with Linux
// AIO and a thread per core waits for them and decodes the blocks (slave/aio_runs.h).
//
// Each loaded block is announced to every thread that asked for it, with one cache pin per
// asker already taken, so it cannot be evicted before they use it.
//
// Thread-safe. A failed read or a damaged block is announced to its askers as an error naming
// the block; the loader never blocks forever on a failure.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <unordered_map>
#include <vector>

#include "common/base/status.h"
#include "common/store/store_reader.h"
#include "slave/aio_runs.h"
#include "slave/block_cache.h"
#include "slave/block_source.h"

namespace raystack::slave {

struct LoaderOptions {
  int io_threads = 32;  // reads in flight: dragon x36 at 1 ms per read, 16 -> 32: 2.47 -> 1.69 s; local disk the same
  uint32_t max_run_bytes = 256 << 10;  // neighbouring blocks merged into one read, up to this
};

// What a read and its decoding need: the stored bytes of a run, and the decoder's scratch.
struct ReadBuffers {
  std::vector<uint8_t> bytes;
  store::AlignedBuffer scratch;
};

// ReadBuffers kept from one frame's loader to the next (the engine holds the shelf), so a warm
// frame's reads and decodes touch no memory that is new: each new page is a fault, ~12 us on a
// VM whose host takes freed memory back, and each frame's new I/O threads made ~140 of them a
// frame per slave. Thread-safe.
class BufferShelf {
 public:
  std::unique_ptr<ReadBuffers> Take();  // a kept set, or a new one
  void Put(std::unique_ptr<ReadBuffers> buffers);

 private:
  std::mutex mu_;
  std::vector<std::unique_ptr<ReadBuffers>> kept_;
};

class BlockLoader {
 public:
  static constexpr int kMaxRayThreads = 64;  // requesters are a 64-bit mask
  // Called from loader threads when block `block` is ready for ray thread `thread` (the pin is
  // taken) or failed (`status` names the block; no pin).
  using Deliver = std::function<void(uint32_t thread, uint32_t block, const Status& status)>;

  // Called from a loader thread that cannot go on (out of memory in it: an address-space
  // limit), with a status made without allocating: the frame must fail, or its rays would wait
  // for blocks no thread reads.
  using Fail = std::function<void(const Status& status)>;

  // `shelf`: where the loader's threads take their buffers and put them back when it stops (it
  // must outlive the loader); without one, the loader keeps its own.
  BlockLoader(const store::StoreReader& store, BlockCache* cache, BlockSource* source,
              LoaderOptions options, Deliver deliver, BufferShelf* shelf = nullptr,
              Fail fail = {});
  ~BlockLoader();

  // Ray thread `thread` needs block `block`. Non-blocking.
  void Request(uint32_t block, uint32_t thread);
  // Stops and joins the threads; pending requests are dropped.
  void Stop();

  double busy_seconds() const;  // time with at least one read in flight (T_io)
  // CPU time of the loader and I/O threads (reads, kernel included, and decoding); complete
  // once Stop() has returned.
  double cpu_seconds() const;
  uint64_t batches() const { return batches_.load(); }
  // I/O workers started so far (at most LoaderOptions::io_threads). Call after Stop().
  size_t workers() const { return workers_.size(); }
  // Whether direct reads are kept in flight with Linux AIO (slave/aio_runs.h) rather than by
  // a blocking thread each.
  bool aio() const { return aio_ != nullptr; }
  uint64_t aio_submits() const { return aio_ ? aio_->submit_calls() : 0; }  // io_submit calls
  uint64_t runs() const { return runs_.load(); }
  // Runs the loader thread read itself (see the top of this file). Call after Stop().
  uint64_t inline_runs() const { return inline_runs_; }

 private:
  struct Run {
    std::vector<uint32_t> ids;
  };
  void LoaderLoop();
  void WorkerLoop();
  void AioLoop();
  void StartQueuedAio();  // aio_mu_ held
  void CompleteRun(const Run& run, const Status& read, const uint8_t* bytes,
                   store::AlignedBuffer* scratch);
  void Complete(uint32_t block, const Status& status, std::span<const uint8_t> stored,
                store::AlignedBuffer* scratch);
  // To the I/O workers (or AIO); read on the loader thread itself while reads have not waited,
  // if `may_read_here`.
  // A batch's runs (moved from): with AIO all started in one system call, else each as below.
  void Submit(std::vector<Run>* runs, bool may_read_here);
  void Submit(Run run, bool may_read_here);  // one run, without AIO
  void ReadInline(const Run& run);  // on the loader thread
  // Reads `run` from the source and completes its blocks; returns whether the read waited.
  bool ReadAndComplete(const Run& run, std::vector<uint8_t>* bytes, store::AlignedBuffer* scratch);
  bool StartWorker();  // false: the thread could not be started (a limit)
  void StartThreads();  // the constructor's: AIO's, then the loader
  void BusyBegin();
  void BusyEnd();
  void AddCpu(double seconds);

  const store::StoreReader& store_;
  BlockCache* cache_;
  BlockSource* source_;
  const LoaderOptions options_;
  const Deliver deliver_;
  const Fail fail_;
  bool threads_refused_ = false;  // an I/O thread could not start: no more tries (runs_mu_)
  // Runs `loop` (a thread's body); an exception out of it fails the frame (fail_) instead of
  // ending the process (std::terminate).
  void Guarded(void (BlockLoader::*loop)());
  BufferShelf own_shelf_;  // used when none is given
  BufferShelf* const shelf_;

  std::mutex mu_;
  std::condition_variable requests_cv_;
  std::vector<std::pair<uint32_t, uint32_t>> requests_;  // (block, thread)
  std::unordered_map<uint32_t, uint64_t> in_flight_;      // block -> threads waiting for it
  bool stop_ = false;

  // The loader thread reads batches of at most kInlineRunsAtMost runs itself until reads wait
  // (then the workers take every run). Loader thread only.
  static constexpr size_t kInlineRunsAtMost = 4;
  bool read_inline_ = true;
  int waited_in_a_row_ = 0;
  uint64_t inline_runs_ = 0;
  std::unique_ptr<ReadBuffers> inline_buffers_;  // taken when first needed

  std::mutex runs_mu_;
  std::condition_variable runs_cv_;
  std::deque<Run> run_queue_;
  bool workers_stop_ = false;
  size_t idle_workers_ = 0;  // waiting for a run
  const size_t max_workers_;
  size_t allowed_workers_;  // the cores, plus one per read that had to wait (to max_workers_)

  mutable std::mutex busy_mu_;
  int active_ = 0;
  std::chrono::steady_clock::time_point busy_since_;
  double busy_seconds_ = 0;
  double cpu_seconds_ = 0;

  // Direct reads (when the source offers them, slave/aio_runs.h): the loader thread starts
  // them, and the workers (one per core, at most io_threads) wait for them and decode the
  // blocks.
  std::unique_ptr<AioRuns> aio_;
  std::mutex aio_mu_;
  std::condition_variable aio_cv_;  // a read started, or stop
  std::vector<Run> aio_runs_;       // by slot
  std::deque<Run> aio_queue_;       // runs waiting for a slot
  bool aio_stop_ = false;

  std::atomic<uint64_t> batches_{0}, runs_{0};
  std::thread loader_;
  std::vector<std::thread> workers_;
};

}  // namespace raystack::slave
