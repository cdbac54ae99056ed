#include "slave/direct_reads.h"

#include <algorithm>

#include "common/base/byte_sizes.h"
#include "common/base/log.h"
#include "common/base/memory_available.h"

namespace raystack::slave {

Expected<DirectIo> ParseDirectIo(const std::string& name) {
  if (name == "auto") return DirectIo::kAuto;
  if (name == "on") return DirectIo::kOn;
  if (name == "off") return DirectIo::kOff;
  return Status::Error("--direct-io must be auto, on or off, got '" + name + "'");
}

bool AutoDirect(uint64_t store_bytes, uint64_t cache_bytes, std::optional<uint64_t> available) {
  if (!available) return false;
  return *available <= cache_bytes || store_bytes > *available - cache_bytes;
}

Status ChooseReads(DirectIo mode, uint64_t cache_bytes, store::StoreReader* store,
                   std::string* why) {
  const uint64_t stored = store->blocks_file_bytes();
  if (mode == DirectIo::kOff) {
    *why = "buffered (--direct-io off)";
    return OkStatus();
  }
  if (mode == DirectIo::kOn) {
    RAYSTACK_RETURN_IF_ERROR(store->UseDirectReads());
    *why = "direct (--direct-io on)";
    return OkStatus();
  }
  const std::optional<uint64_t> available = MemoryAvailable();
  // The cache never holds more than the decoded store: a --cache-mb far above it took the
  // memory the page cache needs, on paper, and chose direct reads for no reason.
  cache_bytes = std::min(cache_bytes, store->summary().raw_bytes);
  const std::string sizes =
      available ? StrFormat("blocks.bin %s, %s of memory available, cache up to %s",
                            MiB(stored).c_str(), MiB(*available).c_str(), MiB(cache_bytes).c_str())
                : StrFormat("blocks.bin %s, available memory unknown", MiB(stored).c_str());
  if (!AutoDirect(stored, cache_bytes, available)) {
    *why = "buffered (--direct-io auto: " + sizes + ")";
    return OkStatus();
  }
  if (const Status s = store->UseDirectReads(); !s.ok()) {
    *why = "buffered (--direct-io auto: " + sizes + "; " + s.message() + ")";
    return OkStatus();
  }
  *why = "direct (--direct-io auto: " + sizes + ": the page cache cannot keep the store)";
  return OkStatus();
}

}  // namespace raystack::slave
