#pragma once
// The master's side of a distributed frame (rank 0): hands out tiles on request, merges the
// slaves' pixel batches into the film as they arrive, and gathers each slave's figures. It
// sees the slaves only through a Transport (MPI, or ranks as threads in one process).
//
// A lost slave costs time, never pixels: a slave that reports a failure, or whose heartbeat
// stops (killed, its node gone), is dropped for the rest of the job; the samples it sent of
// tiles it had not finished are taken back out of the film and those tiles go to the others
// (TileLedger), and the others are told (RankLost), so with --blocks rem they read its blocks
// from disk. Once every tile is handed out, a request is held back, not refused, until every
// tile is finished: a tile that comes back then still finds a slave to render it.

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "common/base/status.h"
#include "common/render/film.h"
#include "common/render/frame_plan.h"
#include "common/render/tiles.h"
#include "common/transport/transport.h"
#include "common/wire/message.h"

namespace raystack::master {

struct SlaveFigures {
  int rank = 0;
  std::string host;  // where it runs (its hello), for the operator: empty if it never said
  wire::FrameDone done{};  // as the slave reported it
  uint64_t bytes_received = 0;  // by the master from this slave (pixel batches and the rest)
  uint64_t bytes_sent = 0;      // by the master to this slave
  uint64_t pixel_bytes = 0;     // the pixel stream's share of bytes_received
  bool dropped = false;         // lost or failed in this frame (or before): `done` is empty
  std::string failure;          // why it was dropped
};

struct FrameFigures {
  std::vector<SlaveFigures> slaves;  // by slave, rank 1 first
  double seconds = 0;                // the frame on the master's clock
  // Thesis definitions over the slaves' render times.
  double imbalance() const;  // 1 - mean / max of the slaves' times (each from its first tile)
  // The slaves' busy ray-thread time (FrameDone::busy_seconds: tracing, not waiting for blocks
  // or tiles) over the ray-thread time the frame offered them (ray threads x `seconds`), over
  // the slaves that finished. Online, unlike T_1 / (N x T_N), which needs a one-slave run: it
  // says how much of the slaves' time the frame wasted waiting, not what extra work (reloads,
  // a peer's blocks) cost. 0 if unknown.
  double utilisation() const;
};

// What every slave must render alike (its wire::Hello says what it renders): a slave of
// another build, store or scene would merge pixels of another image into this one.
struct JobIdentity {
  std::string build;                  // BuildId()
  std::optional<uint64_t> store;      // StoreChecksum; none where the master cannot read the
                                      // store: then the first slave's is the one
  uint64_t scene = 0;                 // SceneChecksum
  std::optional<bool> remote_blocks;  // --blocks rem; none where the master cannot tell
};

struct MasterOptions {
  // A slave not heard from for this long is lost (it sends a heartbeat every
  // wire::kHeartbeatInterval, whatever it is doing).
  std::chrono::milliseconds lost_after{5000};
  // Before its first word, a slave has this much more (it opens the store, perhaps on a slow
  // network filesystem, before it starts its heartbeat).
  std::chrono::milliseconds first_word_grace{60000};
  // Checked against each slave's hello; none: not checked (tests of the node alone).
  std::optional<JobIdentity> identity;
  // Tell every slave the master is alive every wire::kHeartbeatInterval (from a thread of its
  // own, whatever the master is doing), until Shutdown: a slave whose master has gone silent
  // ends rather than wait for it forever (SlaveNode's master_lost_after).
  bool beat = false;
};

class MasterNode {
 public:
  explicit MasterNode(transport::Transport* net, MasterOptions options = {});
  ~MasterNode();
  MasterNode(const MasterNode&) = delete;
  MasterNode& operator=(const MasterNode&) = delete;

  // Runs frame `frame` until every slave has reported it done: the plan's sweeps one after the
  // other (each sweep's tiles scheduled as TileScheduler does), samples merged into `film`.
  // `keep_going` is called from time to time (a few times a second at least); once it returns
  // false, no more tiles are handed out (a stop rule) and the frame ends when the slaves have
  // finished the tiles they hold. A malformed message ends the frame with an error naming the
  // rank. A slave's failure or loss drops that slave and the frame goes on with the others; the
  // frame fails only when no slave is left (the error then lists why each was dropped).
  Status RunFrame(uint32_t frame, const render::FramePlan& plan, render::Film* film,
                  const std::function<bool()>& keep_going, FrameFigures* figures);
  // All `spp` samples of `tiles` in one sweep (the pre-progressive way; tests, --resume).
  Status RunFrame(uint32_t frame, std::vector<render::Tile> tiles, uint32_t spp,
                  render::Film* film, const std::function<void()>& on_progress,
                  FrameFigures* figures);
  // Tells every slave the job is over (reason 0) or failed (1), then reads (and drops) what
  // they still send until each has acknowledged: a slave blocked sending a pixel batch must be
  // able to finish before every rank ends. False if some slave did not answer within `timeout`
  // (or cannot: it spoke another protocol); the transport is then told it will not end with
  // the job (NoteRankWillNotEnd), which must then be ended by force.
  bool Shutdown(uint32_t reason, std::chrono::milliseconds timeout = std::chrono::seconds(30));
  // Tells every slave the job failed and this rank ends now, without waiting for anything (the
  // master was interrupted): they end at once too, rather than find the master silent later.
  void Abandon();
  // The tiles handed out in the current (or last) frame, per slave (index = rank - 1), in the
  // order given: the latest kPreviewTilesPerSlave of them, which hold those in flight.
  // Thread-safe: the live preview reads it while RunFrame runs.
  static constexpr size_t kPreviewTilesPerSlave = 32;
  std::vector<std::vector<render::Tile>> TilesAssigned() const;
  // Why each slave (index = rank - 1) was dropped from the job, empty while it works.
  // Thread-safe, as TilesAssigned.
  std::vector<std::string> SlavesDropped() const;

 private:
  struct SlaveState {
    std::string host;  // from its hello (empty before it, or when it gave none)
    bool dropped = false;
    bool lost = false;  // dropped for silence: it may be dead, so nothing waits for it
    bool heard = false;  // it has said something since the job began
    bool deaf = false;   // it sent what this build cannot read: it cannot read this build either
    std::string failure;
    std::chrono::steady_clock::time_point last_heard;
  };
  struct Frame;  // one RunFrame's working state
  Status Send(int to, const std::vector<uint8_t>& bytes, FrameFigures* figures);
  Status Handle(Frame* f, transport::Envelope e);
  bool NextTile(Frame* f, int rank, render::Tile* t);
  bool WorkLeft(const Frame& f) const;
  Status Answer(Frame* f, int rank, uint32_t thread);
  Status AnswerHeldRequests(Frame* f);
  // Drops `rank` for the rest of the job: its unfinished tiles go back to the others.
  Status Drop(Frame* f, int rank, bool lost, const std::string& why);
  Status CheckHeartbeats(Frame* f);
  Status CheckHello(int rank, const wire::Hello& hello);
  void StopBeating();

  transport::Transport* net_;
  MasterOptions options_;
  std::vector<SlaveState> slaves_;  // by rank (0: unused)
  int store_from_ = 0;  // the slave whose store the others must match (0: the master's)
  // When CheckHeartbeats last looked (or the master last listened): a longer gap is time the
  // master itself was busy, not the slaves' silence.
  std::chrono::steady_clock::time_point last_check_;
  // Messages for a later frame that arrived early (a fast slave's first requests).
  std::deque<transport::Envelope> early_;
  mutable std::mutex assigned_mu_;
  std::vector<std::vector<render::Tile>> assigned_;  // guarded by assigned_mu_
  std::vector<std::string> dropped_;  // guarded by assigned_mu_; for the whole job
  std::mutex beat_mu_;
  std::condition_variable beat_stop_;
  bool beating_ = false;  // guarded by beat_mu_
  std::thread beater_;
};

}  // namespace raystack::master
