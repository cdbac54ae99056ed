#pragma once
// How ranks talk: bytes from one rank to another, in order per pair of ranks. The master and
// the slaves see only this interface (OSPRay's Fabric); MPI is one backend (common/mpi/, the
// only code that includes mpi.h), and an in-process backend runs every rank as a thread of one
// process, for one-process runs and for tests that need no mpirun.
//
// Send, Post and Receive may be called from different threads; Receive from one thread at a
// time.
// Failures (a peer gone, a message too large) are returned, never thrown.

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <vector>

#include "common/base/status.h"

namespace raystack::transport {

// Largest message a transport accepts (a pixel batch of 65,536 samples is 3.4 MB).
inline constexpr uint64_t kMaxMessageBytes = 16 << 20;

struct Envelope {
  int from = -1;
  std::vector<uint8_t> bytes;
};

class Transport {
 public:
  virtual ~Transport() = default;
  virtual int rank() const = 0;
  virtual int size() const = 0;
  // The ranks on this rank's machine, which share its memory: how many (this one included),
  // and whether rank 0 is one of them. The default: this rank alone.
  struct HostShare {
    int ranks = 1;
    bool with_rank0 = false;
  };
  virtual HostShare host_share() const { return {1, rank() == 0}; }
  // Queues `bytes` for rank `to` (0 <= to < size()); returns once they may be reused.
  virtual Status Send(int to, std::span<const uint8_t> bytes) = 0;
  // Queues `bytes` for rank `to` and returns at once, whether or not `to` has begun to receive
  // them: the transport owns them until they are sent. For answers sent by a receiving thread,
  // which must never wait for a peer (two receivers each sending the other a large answer with
  // Send would wait for each other forever). Same order per pair as Send. A failure found later
  // is returned by a later Receive or Post. The default, for transports whose Send never
  // waits: Send.
  virtual Status Post(int to, std::vector<uint8_t> bytes) { return Send(to, bytes); }
  // Bytes handed to Post and not sent yet: a stream's sender bounds its backlog with it
  // rather than wait for every message (Send) or let a slow receiver's backlog grow.
  virtual uint64_t posted_bytes() const { return 0; }
  // The next message for this rank, waiting up to `timeout`; nullopt if none came.
  virtual Expected<std::optional<Envelope>> Receive(std::chrono::milliseconds timeout) = 0;
  // For a backend that polls (MPI): while no thread of this rank waits for an answer, Receive
  // may look for messages only every `pause` (a look costs a capped node CPU its work needs);
  // between BeginWait and EndWait (an AnswerWait) it looks at its quickest, from at once.
  // Zero, the default: always at its quickest (a master, which serves every message at once).
  virtual void SetIdlePause(std::chrono::microseconds /*pause*/) {}
  virtual void BeginWait() {}
  virtual void EndWait() {}
  // Rank `rank` died (killed, its node gone; -1: some rank, which one this rank was not told):
  // a send to it gives up rather than wait for it forever, and the job cannot end in step
  // with it (MPI_Finalize would wait for it too).
  virtual void NoteRankDied(int /*rank*/) {}
  // Whether rank `rank` was noted dead (sends to it give up).
  virtual bool dead(int /*rank*/) const { return false; }
  // Rank `rank` is alive but will not end with the job (it cannot read this build's messages,
  // or did not acknowledge the end): this rank must end it by force once done.
  virtual void NoteRankWillNotEnd(int /*rank*/) {}
};

// A thread of this rank waits for an answer while this lives (Transport::BeginWait).
class AnswerWait {
 public:
  explicit AnswerWait(Transport* net) : net_(net) { net_->BeginWait(); }
  ~AnswerWait() { net_->EndWait(); }
  AnswerWait(const AnswerWait&) = delete;
  AnswerWait& operator=(const AnswerWait&) = delete;

 private:
  Transport* net_;
};

// Every rank as a thread of this process: Endpoint(r) is rank r's transport. The hub must
// outlive its endpoints.
class InProcessHub {
 public:
  explicit InProcessHub(int ranks);
  std::unique_ptr<Transport> Endpoint(int rank);
  int ranks() const { return static_cast<int>(boxes_.size()); }

 private:
  friend class InProcessTransport;
  struct Mailbox {
    std::mutex mu;
    std::condition_variable cv;
    std::deque<Envelope> queue;
  };
  std::vector<std::unique_ptr<Mailbox>> boxes_;
};

}  // namespace raystack::transport
