#pragma once
// --direct-io: whether the loader reads blocks.bin past the kernel's page cache (O_DIRECT).
// When the page cache can keep the store, it is a free second-level cache: blocks the block
// cache drops come back from memory, and slaves on one machine share one copy. When it
// cannot (a store larger than the machine's memory, or than a cgroup limit), every block
// passes through it for nothing: inserted, copied out, then reclaimed, by the reading thread
// itself under a cgroup limit. Direct reads skip that (tools/bench/RESULTS.md: the loader's
// CPU per block -16%, and no kernel readahead, so a blocking `sync` baseline waits for every
// read it makes), and the stack's loader keeps them in flight with Linux AIO instead of a
// thread each (slave/aio_runs.h: a further -20%).

#include <cstdint>
#include <optional>
#include <string>

#include "common/base/status.h"
#include "common/store/store_reader.h"

namespace raystack::slave {

enum class DirectIo { kAuto, kOn, kOff };

Expected<DirectIo> ParseDirectIo(const std::string& name);

// auto's rule: direct when blocks.bin does not fit the memory available (`available`, from
// MemoryAvailable) next to the block cache's budget. Unknown memory: buffered.
bool AutoDirect(uint64_t store_bytes, uint64_t cache_bytes, std::optional<uint64_t> available);

// Applies `mode` to `store` and says what it chose, and why, in `*why`. With kOn a filesystem
// that refuses direct reads is an error naming the file; with kAuto the reads stay buffered
// and `*why` says so.
Status ChooseReads(DirectIo mode, uint64_t cache_bytes, store::StoreReader* store,
                   std::string* why);

}  // namespace raystack::slave
