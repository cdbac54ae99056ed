#include "slave/block_source.h"

#include <chrono>
#include <thread>

#include "common/base/log.h"

namespace raystack::slave {

Status DiskBlockSource::ReadRun(std::span<const uint32_t> ids, std::vector<uint8_t>* bytes) {
  const int64_t k = reads_.fetch_add(1);
  const auto entries = store_.blocks();
  const store::BlockEntry& first = entries[ids.front()];
  const store::BlockEntry& last = entries[ids.back()];
  const uint64_t size = last.offset + last.stored_bytes - first.offset;
  if (faults_.io_latency_us > 0)
    std::this_thread::sleep_for(std::chrono::microseconds(faults_.io_latency_us));
  if (k == faults_.fail_read)
    return Status::Error(StrFormat("%s/blocks.bin: block %u at offset %llu: read failed (injected fault)",
                                   store_.dir().c_str(), ids.front(),
                                   static_cast<unsigned long long>(first.offset)));
  bytes->resize(size);
  RAYSTACK_RETURN_IF_ERROR(store_.ReadRange(first.offset, size, bytes->data()));
  bytes_.fetch_add(size);
  if (k == faults_.corrupt_read && size > 0) (*bytes)[size / 2] ^= 0x5a;
  return OkStatus();
}

}  // namespace raystack::slave
