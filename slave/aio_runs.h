#pragma once
// Reads of block runs from blocks.bin opened O_DIRECT, kept in flight by the thread that
// submits them, with Linux native AIO (io_submit, io_getevents). The loader's alternative is a
// blocking pread per I/O thread, 32 threads for 32 reads in flight: each read then costs its
// thread a sleep and a wake-up, ~16 us of kernel CPU per 32 KB read in a stack run, against
// ~5 us when submitted in batches (tools/bench/RESULTS.md). Native AIO is only asynchronous
// for direct reads, which is where a store is too large for the page cache anyway.
//
// Raw system calls: glibc has no wrappers, and libaio would be a package for four calls
// (liburing's io_uring, the newer interface, likewise; this kernel API is enough for reads).

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

#include "common/base/status.h"
#include "common/store/store_reader.h"

struct iocb;  // <linux/aio_abi.h>

namespace raystack::slave {

class DiskBlockSource;

class AioRuns {
 public:
  struct Finished {
    int slot;  // what Start returned; Release(slot) once the bytes are used
    Status status;
    std::span<uint8_t> bytes;  // the run's stored bytes when status is ok
  };

  // nullptr when the kernel refuses an AIO context (no AIO support, or the system's
  // fs.aio-max-nr used up): the caller reads with threads instead, which it logs.
  static std::unique_ptr<AioRuns> Open(const store::StoreReader& store, DiskBlockSource* disk,
                                       int depth);
  ~AioRuns();  // waits for the reads in flight (their buffers are freed after)
  AioRuns(const AioRuns&) = delete;
  AioRuns& operator=(const AioRuns&) = delete;

  // Readies a read of run `ids` (consecutive blocks) and returns its slot, or -1 when `depth`
  // slots are taken; SubmitPrepared starts every read readied so far with one system call, so
  // a batch of runs costs the disk one notification (in a virtual machine, each is an exit:
  // ~19 us of the loader's CPU on a PVM guest). A read that fails to start finishes at once,
  // with the error. Thread-safe.
  int Prepare(std::span<const uint32_t> ids);
  void SubmitPrepared();
  int Start(std::span<const uint32_t> ids);  // Prepare, then SubmitPrepared
  // Waits up to `timeout_ms` for at least one read to finish and appends up to `max` finished
  // ones. Thread-safe: each finished read goes to one caller.
  void Wait(int timeout_ms, int max, std::vector<Finished>* finished);
  void Release(int slot);  // Thread-safe.
  int in_flight() const;   // slots taken. Thread-safe.
  uint64_t submit_calls() const { return submit_calls_.load(); }  // io_submit calls made

 private:
  struct Slot;
  AioRuns(const store::StoreReader& store, DiskBlockSource* disk, unsigned long context,
          int depth);
  Status Fill(Slot* slot, std::span<const uint32_t> ids);  // the slot's request
  Status StartFailure(const Slot& slot, const char* why) const;

  const store::StoreReader& store_;
  DiskBlockSource* const disk_;
  const unsigned long context_;  // aio_context_t
  std::vector<std::unique_ptr<Slot>> slots_;

  mutable std::mutex mu_;
  std::vector<int> free_;        // slots not in use
  std::vector<Finished> failed_;  // reads that failed to start, reported by the next Wait
  std::vector<iocb*> prepared_;   // readied, not yet submitted (aio_data: the slot)
  std::atomic<uint64_t> submit_calls_{0};
};

}  // namespace raystack::slave
