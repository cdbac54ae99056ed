#include "slave/block_source.h"

#include <chrono>
#include <new>
#include <thread>

#include "common/base/log.h"
#include "slave/aio_runs.h"

namespace raystack::slave {

Status DiskBlockSource::BeginRead(std::span<const uint32_t> ids, int64_t* k) {
  *k = reads_.fetch_add(1);
  if (*k != faults_.fail_read) return OkStatus();
  const store::BlockEntry& first = store_.blocks()[ids.front()];
  return Status::Error(StrFormat("%s/blocks.bin: block %u at offset %llu: read failed (injected fault)",
                                 store_.dir().c_str(), ids.front(),
                                 static_cast<unsigned long long>(first.offset)));
}

void DiskBlockSource::EndRead(int64_t k, std::span<uint8_t> bytes) {
  bytes_.fetch_add(bytes.size());
  if (k == faults_.corrupt_read && !bytes.empty()) bytes[bytes.size() / 2] ^= 0x5a;
}

Status DiskBlockSource::ReadRun(std::span<const uint32_t> ids, std::vector<uint8_t>* bytes) {
  const store::StoreReader::Extent run = store_.RunExtent(ids.front(), ids.back());
  int64_t k;
  const Status begun = BeginRead(ids, &k);
  if (faults_.io_latency_us > 0)
    std::this_thread::sleep_for(std::chrono::microseconds(faults_.io_latency_us));
  RAYSTACK_RETURN_IF_ERROR(begun);
  try {
    bytes->resize(run.size);
    RAYSTACK_RETURN_IF_ERROR(store_.ReadRange(run.offset, run.size, bytes->data()));
  } catch (const std::bad_alloc&) {  // (an address-space limit): the read fails
    return Status::Error(kOutOfMemory);  // nothing allocated here (status.h)
  }
  EndRead(k, *bytes);
  return OkStatus();
}

std::unique_ptr<AioRuns> DiskBlockSource::OpenAio(int depth) {
  // An injected latency stands for a network filesystem's, slept by the reading thread: it
  // needs the threads. Buffered reads from the page cache would run inside io_submit.
  if (!store_.direct_reads() || faults_.io_latency_us > 0) return nullptr;
  return AioRuns::Open(store_, this, depth);
}

}  // namespace raystack::slave
