#pragma once
// --blocks rem (thesis VI.2): the store's blocks are spread over the slaves' memories by a
// static owner map (contiguous ranges of block ids, so an owner's reads stay neighbours on
// disk). A slave that misses a block fetches it from its owner's memory; the owner reads each
// of its blocks from disk once, on first use, and keeps its stored (compressed) bytes, which
// the front end charges against that slave's cache budget. So across the job each block is
// read from disk at most once, by its owner.
//
// PeerBlocks is the engine's BlockSource: a run of blocks comes from this slave's own share or
// from the owners'. Requests to one owner are batched: at most kMaxInFlightPerOwner requests
// are out to an owner at a time, and the runs the loader's workers want from it meanwhile
// queue in one open batch, sent as a single request (several runs) when an answer comes back.
// Under a CPU cap every message costs both ends wake-ups that may wait for the node's next
// slice; batched, N = 8 slaves send 40% fewer (tools/bench/RESULTS.md). Each batch's fetches
// wait on a condition variable of the batch (an answer wakes its fetchers only) and take their
// own run's bytes out of the answer: the loader's cache budget sees exactly the blocks it
// asked for.
// The owner answers a request for blocks it holds already right on the receiving thread, with
// a posted (non-blocking) send: no thread hop. A request that needs a disk read goes to a
// server thread, so a slow disk never holds up the receiving thread. Requests and answers are
// plain wire messages; an answer is checked against the index (sizes) before it is used, and
// every block is checked again by its checksum when decoded.
//
// Thread-safe. The slave's receiving thread hands peer messages in with OnRequest / OnData.

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <span>
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
  // Requests sent to owners, and the time they took from send to answer (summed over
  // requests): where --blocks rem's time goes. runs_fetched: the loader's runs they carried
  // (runs_fetched / fetches is the batching).
  uint64_t fetches() const { return fetches_.load(); }
  double fetch_wait_seconds() const { return static_cast<double>(fetch_wait_ns_.load()) * 1e-9; }
  uint64_t runs_fetched() const { return runs_fetched_.load(); }
  // Runs waiting in batches not sent yet (for tests: the batching is observable).
  uint64_t runs_waiting() const {
    std::lock_guard lock(mu_);
    return runs_waiting_;
  }

  // Requests out to one owner at a time; the runs wanted meanwhile wait in one batch.
  static constexpr int kMaxInFlightPerOwner = 2;
  // A batch is sent at once (whatever is in flight) when one more run would take it beyond
  // these: bounded answers, and a fetch never waits behind an ever-growing batch.
  static constexpr uint32_t kMaxBatchRuns = 64;
  static constexpr uint64_t kMaxBatchBytes = 2 << 20;
  // Largest answer an owner sends: a request for more is an error naming the asker.
  static constexpr uint64_t kMaxAnswerBytes = 8 << 20;

  // From the receiving thread (only): a peer's request (a kBlockRequest message: answered at
  // once when its blocks are in memory, else on the server thread), an answer. A malformed one
  // is an error naming the sender. An answer's fetches take their runs from the message's own
  // buffer, `*received` (the bytes `data` was decoded from), which it takes over: not copied.
  Status OnRequest(int from, const wire::Message& request);
  Status OnData(int from, const wire::Message& data, std::vector<uint8_t>* received);
  // Fails every wait for an answer (the job is ending).
  void Stop();
  // `rank` is gone (the master said so): its blocks are read from disk from now on, and the
  // fetches waiting for its answers read them from disk instead.
  void OwnerLost(int rank);
  // The first failure to read this slave's own share for a peer (its disk, or its copy of the
  // store, failed): the slave fails on it as on a failed read for its own rays, so a broken
  // disk drops the slave whoever the read was for. Given once; OK when there was none.
  Status TakeServeFailure();

 private:
  // One request to one owner: the runs of the fetches that joined it, in the order they joined;
  // the answer holds their bytes back to back in that order.
  struct Batch {
    int owner = 0;
    uint32_t request = 0;  // its number, once sent
    bool sent = false, full = false, done = false;
    // Its owner was lost, or could not read the runs: the askers read them from disk instead.
    bool from_disk = false;
    Status status;
    std::vector<wire::BlockRun> runs;
    uint64_t expected_bytes = 0;  // the index's stored bytes of the runs
    int members = 0;              // fetches that have not taken their bytes yet
    std::vector<uint8_t> message;    // the answer as received
    std::span<const uint8_t> bytes;  // its runs' stored bytes, back to back (in `message`)
    std::condition_variable cv;   // its fetches wait here
  };
  struct OwnerQueue {
    int in_flight = 0;             // requests sent, not answered
    std::shared_ptr<Batch> open;   // collecting runs until it may be sent
  };
  struct Served {
    int to;
    uint32_t request;
    std::vector<wire::BlockRun> runs;
  };
  // This slave's own block, read from disk on first use.
  Status Own(uint32_t block, std::vector<uint8_t>* append);
  Status Fetch(int owner, uint32_t first, uint32_t count, std::vector<uint8_t>* append);
  // Sends the open batch `b` (holds mu_ through `lock`, which it releases while sending).
  void SendBatch(const std::shared_ptr<Batch>& b, std::unique_lock<std::mutex>* lock);
  uint64_t RunBytes(uint32_t first, uint32_t count) const;
  // A request to `q`'s owner is no longer out (answered, failed or given up): the open batch
  // may go. Holds mu_.
  void Answered(OwnerQueue* q);
  // Sends `to` the answer to request `request` for `runs`, their blocks read (from memory or
  // disk) into `scratch`.
  void Answer(int to, uint32_t request, std::span<const wire::BlockRun> runs,
              std::vector<uint8_t>* scratch);
  void ServeLoop();

  transport::Transport* net_;
  const store::StoreReader& store_;
  DiskBlockSource disk_;
  const int slaves_;
  uint32_t own_first_ = 0, own_end_ = 0;  // this slave's share [own_first_, own_end_)
  uint64_t owned_bytes_ = 0;
  struct OwnedBlock {
    std::once_flag loaded;
    std::atomic<bool> ready{false};  // loaded (or failed): Own will not read the disk
    Status status;
    std::vector<uint8_t> bytes;
  };
  std::vector<OwnedBlock> owned_;

  mutable std::mutex mu_;
  std::condition_variable serve_cv_;  // the server thread waits here
  uint64_t runs_waiting_ = 0;
  std::vector<OwnerQueue> owners_;    // by rank
  std::unordered_map<uint32_t, std::shared_ptr<Batch>> sent_;  // by request number
  uint32_t next_request_ = 0;
  bool stopped_ = false;
  std::vector<bool> lost_;  // by rank
  std::deque<Served> to_serve_;
  Status serve_failure_;  // see TakeServeFailure
  bool serve_failure_taken_ = false;
  std::vector<uint8_t> receive_scratch_;  // answers built on the receiving thread
  std::vector<wire::BlockRun> receive_runs_;
  std::thread server_;

  std::atomic<uint64_t> reads_{0}, bytes_{0}, from_peers_{0}, to_peers_{0};
  std::atomic<uint64_t> fetches_{0}, fetch_wait_ns_{0}, runs_fetched_{0};
};

}  // namespace raystack::slave
