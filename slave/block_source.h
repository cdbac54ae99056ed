#pragma once
// Where the loader gets block bytes: the store's blocks.bin on a local disk or a shared
// filesystem (`--blocks loc`, DiskBlockSource), or the slaves' memories (`--blocks rem`,
// PeerBlocks in peer_blocks.h). One virtual call per read run, never per ray. Fault injection
// lives in the disk source so every loader path can be tested against it.

#include <atomic>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "common/base/status.h"
#include "common/store/store_reader.h"
#include "slave/aio_runs.h"

namespace raystack::slave {

struct FaultOptions {
  uint32_t io_latency_us = 0;  // added to every read (emulates NFS/Lustre, ~1 ms)
  int64_t fail_read = -1;      // the k-th read (0-based) fails, as a disk error would
  int64_t corrupt_read = -1;   // the k-th read returns one flipped byte (the checksum must catch it)
};

class BlockSource {
 public:
  virtual ~BlockSource() = default;
  // Reads the stored (compressed) bytes of `ids`, which are consecutive in blocks.bin, into
  // `bytes`, in one request. Thread-safe.
  virtual Status ReadRun(std::span<const uint32_t> ids, std::vector<uint8_t>* bytes) = 0;
  virtual uint64_t reads() const = 0;       // ReadRun calls so far
  virtual uint64_t bytes_read() const = 0;  // stored bytes delivered so far
  // Reads kept in flight by one thread, with up to `depth` at once (slave/aio_runs.h), where
  // the source can (a disk read direct); nullptr where it cannot, and the loader then keeps
  // them in flight with a thread each.
  virtual std::unique_ptr<AioRuns> OpenAio(int /*depth*/) { return nullptr; }
};

class DiskBlockSource final : public BlockSource {
 public:
  DiskBlockSource(const store::StoreReader& store, FaultOptions faults)
      : store_(store), faults_(faults) {}
  Status ReadRun(std::span<const uint32_t> ids, std::vector<uint8_t>* bytes) override;
  std::unique_ptr<AioRuns> OpenAio(int depth) override;

  // The two ends of every read, by ReadRun or by AioRuns: counts it as read number `*k` and
  // fails it if that is the injected failure; then counts its bytes and flips one if it is the
  // injected corruption.
  Status BeginRead(std::span<const uint32_t> ids, int64_t* k);
  void EndRead(int64_t k, std::span<uint8_t> bytes);

  uint64_t reads() const override { return reads_.load(); }
  uint64_t bytes_read() const override { return bytes_.load(); }

 private:
  const store::StoreReader& store_;
  FaultOptions faults_;
  std::atomic<int64_t> reads_{0};
  std::atomic<uint64_t> bytes_{0};
};

}  // namespace raystack::slave
