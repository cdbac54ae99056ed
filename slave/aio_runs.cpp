#include "slave/aio_runs.h"

#include <linux/aio_abi.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

#include "common/base/check.h"
#include "common/base/log.h"
#include "slave/block_source.h"

namespace raystack::slave {
namespace {

long IoSetup(unsigned events, aio_context_t* context) {
  return ::syscall(SYS_io_setup, events, context);
}
long IoDestroy(aio_context_t context) { return ::syscall(SYS_io_destroy, context); }
long IoSubmit(aio_context_t context, long count, iocb** requests) {
  return ::syscall(SYS_io_submit, context, count, requests);
}
long IoGetEvents(aio_context_t context, long min, long max, io_event* events, timespec* timeout) {
  return ::syscall(SYS_io_getevents, context, min, max, events, timeout);
}

}  // namespace

struct AioRuns::Slot {
  int index = 0;
  iocb request{};
  store::DirectBuffer buffer;  // the aligned span around the run
  store::DirectSpan span;
  uint64_t offset = 0;  // the run's offset in blocks.bin
  uint64_t size = 0;    // the run's bytes
  int64_t read = 0;     // DiskBlockSource's read number (fault injection)
};

std::unique_ptr<AioRuns> AioRuns::Open(const store::StoreReader& store, DiskBlockSource* disk,
                                       int depth) {
  CHECK(store.direct_fd() >= 0 && depth > 0);
  aio_context_t context = 0;
  if (IoSetup(static_cast<unsigned>(depth), &context) != 0) {
    LOG_WARNING("loader", "%s/%s: no Linux AIO context for %d reads (%s); reading with threads",
                store.dir().c_str(), store::kBlocksFile, depth, std::strerror(errno));
    return nullptr;
  }
  return std::unique_ptr<AioRuns>(new AioRuns(store, disk, context, depth));
}

AioRuns::AioRuns(const store::StoreReader& store, DiskBlockSource* disk, unsigned long context,
                 int depth)
    : store_(store), disk_(disk), context_(context) {
  for (int i = 0; i < depth; ++i) {
    slots_.push_back(std::make_unique<Slot>());
    slots_.back()->index = i;
    free_.push_back(depth - 1 - i);
  }
}

AioRuns::~AioRuns() {
  // io_destroy cancels what it can and waits for the rest, so no read lands in a freed buffer.
  IoDestroy(context_);
}

int AioRuns::in_flight() const {
  std::lock_guard lock(mu_);
  return static_cast<int>(slots_.size() - free_.size());
}

int AioRuns::Start(std::span<const uint32_t> ids) {
  const int slot = Prepare(ids);
  SubmitPrepared();
  return slot;
}

int AioRuns::Prepare(std::span<const uint32_t> ids) {
  Slot* slot;
  {
    std::lock_guard lock(mu_);
    if (free_.empty()) return -1;
    slot = slots_[free_.back()].get();
    free_.pop_back();
  }
  Status s = Fill(slot, ids);
  std::lock_guard lock(mu_);
  if (s.ok()) {
    prepared_.push_back(&slot->request);
  } else {
    failed_.push_back({slot->index, std::move(s), {}});
  }
  return slot->index;
}

void AioRuns::SubmitPrepared() {
  // Per thread, so the swap below trades buffers instead of allocating one per call.
  thread_local std::vector<iocb*> requests;
  requests.clear();
  {
    std::lock_guard lock(mu_);
    requests.swap(prepared_);
  }
  size_t done = 0;
  while (done < requests.size()) {
    const long n =
        IoSubmit(context_, static_cast<long>(requests.size() - done), requests.data() + done);
    submit_calls_.fetch_add(1, std::memory_order_relaxed);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {  // the first of the rest cannot start (n = 0: the kernel took none)
      const Slot& slot = *slots_[requests[done]->aio_data];
      std::lock_guard lock(mu_);
      failed_.push_back(
          {slot.index, StartFailure(slot, n < 0 ? std::strerror(errno) : "not submitted"), {}});
      ++done;
      continue;
    }
    done += static_cast<size_t>(n);
  }
}

Status AioRuns::StartFailure(const Slot& slot, const char* why) const {
  return Status::Error(StrFormat("%s/%s: direct read at offset %llu could not start: %s",
                                 store_.dir().c_str(), store::kBlocksFile,
                                 static_cast<unsigned long long>(slot.span.begin), why));
}

Status AioRuns::Fill(Slot* slot, std::span<const uint32_t> ids) {
  RAYSTACK_RETURN_IF_ERROR(disk_->BeginRead(ids, &slot->read));
  const store::StoreReader::Extent run = store_.RunExtent(ids.front(), ids.back());
  slot->offset = run.offset;
  slot->size = run.size;
  RAYSTACK_RETURN_IF_ERROR(store_.CheckRange(slot->offset, slot->size));
  slot->span = store::DirectSpanOf(slot->offset, slot->size);
  const store::DirectSpan& d = slot->span;
  slot->request = iocb{};
  slot->request.aio_data = static_cast<uint64_t>(slot->index);
  slot->request.aio_lio_opcode = IOCB_CMD_PREAD;
  slot->request.aio_fildes = static_cast<uint32_t>(store_.direct_fd());
  slot->request.aio_buf = reinterpret_cast<uint64_t>(slot->buffer.Reserve(d.end - d.begin));
  slot->request.aio_nbytes = d.end - d.begin;
  slot->request.aio_offset = static_cast<int64_t>(d.begin);
  return OkStatus();
}

void AioRuns::Wait(int timeout_ms, int max, std::vector<Finished>* finished) {
  {
    std::lock_guard lock(mu_);
    if (!failed_.empty()) {
      for (Finished& f : failed_) finished->push_back(std::move(f));
      failed_.clear();
      timeout_ms = 0;  // report these now; collect whatever else has finished meanwhile
    }
  }
  io_event events[64];
  timespec timeout{timeout_ms / 1000, (timeout_ms % 1000) * 1000000L};
  const long got =
      IoGetEvents(context_, timeout_ms > 0 ? 1 : 0, std::clamp(max, 1, 64), events, &timeout);
  for (long i = 0; i < got; ++i) {
    Slot* slot = slots_[events[i].data].get();
    const int64_t result = events[i].res;
    const std::span<uint8_t> bytes(slot->buffer.data() + slot->span.skip, slot->size);
    if (result < 0) {
      finished->push_back(
          {slot->index,
           Status::Error(StrFormat("%s/%s: direct read at offset %llu failed: %s",
                                   store_.dir().c_str(), store::kBlocksFile,
                                   static_cast<unsigned long long>(slot->offset),
                                   std::strerror(static_cast<int>(-result)))),
           {}});
      continue;
    }
    if (static_cast<uint64_t>(result) < slot->span.needed) {
      // A short read: the file ends early (cut while open), or the kernel stopped part way.
      // The blocking read finishes what it can and names the place where it cannot.
      if (Status s = store_.ReadRange(slot->offset, slot->size, bytes.data()); !s.ok()) {
        finished->push_back({slot->index, std::move(s), {}});
        continue;
      }
    }
    disk_->EndRead(slot->read, bytes);
    finished->push_back({slot->index, OkStatus(), bytes});
  }
}

void AioRuns::Release(int slot) {
  std::lock_guard lock(mu_);
  free_.push_back(slot);
}

}  // namespace raystack::slave
