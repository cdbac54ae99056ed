#pragma once
// --blocks rem (thesis VI.2): the store's blocks are spread over the slaves' memories by a
// static owner map (contiguous ranges of block ids, so an owner's reads stay neighbours on
// disk). A slave that misses a block fetches it from its owner's memory; the owner reads each
// of its blocks from disk once, on first use, and keeps its stored (compressed) bytes, which
// the front end charges against that slave's cache budget. So across the job each block is
// read from disk at most once, by its owner.
//
// PeerBlocks is the engine's BlockSource: a run of blocks comes from this slave's own share or
// from the owners' (one request per owner per run; the loader's worker waits for the answer
// while others go on). The owner side answers requests on a server thread of its own, so
// serving peers never holds up the receiving thread. Requests and answers are plain wire
// messages; an answer is checked against the index (sizes) before it is used, and every block
// is checked again by its checksum when decoded.
//
// Thread-safe. The slave's receiving thread hands peer messages in with OnRequest / OnData.

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <thread>
#include <unordered_map>
#include <vector>

#include "common/store/store_reader.h"
#include "common/transport/transport.h"
#include "common/wire/message.h"
#include "slave/block_source.h"

namespace raystack::slave {

// Owner of `block` among `slaves` slaves whose ranks start at 1.
inline int BlockOwner(uint32_t block, uint32_t block_count, int slaves) {
  return 1 + static_cast<int>(uint64_t{block} * static_cast<uint64_t>(slaves) / block_count);
}

class PeerBlocks final : public BlockSource {
 public:
  PeerBlocks(transport::Transport* net, const store::StoreReader& store, FaultOptions faults);
  ~PeerBlocks() override;

  Status ReadRun(std::span<const uint32_t> ids, std::vector<uint8_t>* bytes) override;
  uint64_t reads() const override { return reads_.load(); }
  uint64_t bytes_read() const override { return bytes_.load(); }

  // Stored bytes of this slave's share (what it keeps for its peers once all are used).
  uint64_t owned_bytes() const { return owned_bytes_; }
  uint64_t disk_reads() const { return disk_.reads(); }  // blocks read from disk (own share)
  uint64_t bytes_from_peers() const { return from_peers_.load(); }
  uint64_t bytes_to_peers() const { return to_peers_.load(); }

  // From the receiving thread: a peer's request (answered on the server thread), an answer.
  Status OnRequest(int from, const wire::BlockRequest& request);
  Status OnData(int from, const wire::Message& data);
  // Fails every wait for an answer (the job is ending).
  void Stop();
  // `rank` is gone (the master said so): its blocks are read from disk from now on, and the
  // fetches waiting for its answers read them from disk instead.
  void OwnerLost(int rank);

 private:
  struct Pending {
    int owner;
    uint32_t first, count;
    bool done = false;
    bool owner_lost = false;  // read them from disk instead
    Status status;
    std::vector<uint8_t> bytes;
  };
  struct Served {
    int to;
    wire::BlockRequest request;
  };
  // This slave's own block, read from disk on first use.
  Status Own(uint32_t block, std::vector<uint8_t>* append);
  Status Fetch(int owner, uint32_t first, uint32_t count, std::vector<uint8_t>* append);
  void ServeLoop();

  transport::Transport* net_;
  const store::StoreReader& store_;
  DiskBlockSource disk_;
  const int slaves_;
  uint32_t own_first_ = 0, own_end_ = 0;  // this slave's share [own_first_, own_end_)
  uint64_t owned_bytes_ = 0;
  struct OwnedBlock {
    std::once_flag loaded;
    Status status;
    std::vector<uint8_t> bytes;
  };
  std::vector<OwnedBlock> owned_;

  std::mutex mu_;
  std::condition_variable cv_;
  std::unordered_map<uint32_t, Pending> pending_;
  uint32_t next_request_ = 0;
  bool stopped_ = false;
  std::vector<bool> lost_;  // by rank
  std::deque<Served> to_serve_;
  std::thread server_;

  std::atomic<uint64_t> reads_{0}, bytes_{0}, from_peers_{0}, to_peers_{0};
};

}  // namespace raystack::slave
