#pragma once
// A slave's side of a distributed frame (ranks 1..N): its render engine pulls tiles from the
// master and pushes finished samples back to it, through a Transport. The ray threads ask for
// tiles through RemoteTiles, which keeps two tiles in reserve per thread (requested once the
// current tile is --tile-ahead done), so a tile request's round trip hides behind work; samples
// are posted in batches from the ray threads as they finish (the engine's result batch, ~1000
// samples), in the order their pixels' priorities gave them.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <thread>

#include "common/base/status.h"
#include "common/render/camera.h"
#include "common/render/material_table.h"
#include "common/render/scene.h"
#include "common/transport/transport.h"
#include "slave/render_engine.h"
#include "slave/render_stats.h"

namespace raystack::slave {

class RemoteTiles;
class PeerBlocks;

// Fault injection (tests and drills), at the node's N-th tile of the job (> 0; -1: never).
struct NodeFaults {
  int64_t kill_after_tiles = -1;   // the process kills itself with SIGKILL, as `kill -9` would
  int64_t stall_after_tiles = -1;  // the whole process stops (SIGSTOP), as a stalled node,
  double stall_seconds = 0;        // for this long
};

// A receiving thread runs for the node's whole life: tile assignments for the frame being
// rendered, the master's shutdown, and (with --blocks rem) the peers' block requests and
// answers, which must be served between frames and after this slave's last frame too.
class SlaveNode {
 public:
  // `master_lost_after`: the master beats every wire::kHeartbeatInterval while the job runs
  // (MasterOptions::beat); past this long without a word from it (plus kMasterFirstWordGrace
  // before its first) it is taken for gone (killed, its node lost, this host cut off), and the
  // node fails rather than wait for it forever. Zero: never (a master that does not beat).
  SlaveNode(transport::Transport* net, RenderEngine* engine, PeerBlocks* peers = nullptr,
            NodeFaults faults = {}, std::chrono::milliseconds master_lost_after = {});
  ~SlaveNode();

  // Renders this slave's share of frame `frame`, then reports it done (with its figures) to
  // the master. On failure the master is told why (an error message) before this returns it,
  // unless the failure is the master's own shutdown.
  Status RunFrame(uint32_t frame, const render::Scene& scene,
                  const render::MaterialTable& materials, const render::Camera& camera,
                  RenderStats* stats);
  // Waits for the master's shutdown (at most `timeout`; at once if it has come), acknowledges
  // it (once per node, whoever noticed it first); returns its reason (0: done). Every slave
  // calls it before it ends, also after a failed frame: the master waits for every ack.
  // Fails at once if the master is gone (see the constructor).
  Expected<uint32_t> WaitForShutdown(std::chrono::milliseconds timeout = std::chrono::hours(24 * 365));
  // Whether the master was taken for gone: it cannot end the job, so this rank must end alone.
  bool master_lost() const;

  static constexpr std::chrono::seconds kMasterFirstWordGrace{60};
  // How long after SIGINT or SIGTERM a slave waits for word that the master got it too (its
  // beats say so) before it ends on its own.
  static constexpr std::chrono::seconds kInterruptGrace{3};

 private:
  // How long the receiving thread sleeps between looks for messages while nothing waits for
  // one (Transport::SetIdlePause).
  static constexpr std::chrono::microseconds kIdlePause{5000};
  void ReceiveLoop();
  // Returns once the frame's posted pixel batches are out (or after a while).
  void FlushPixels();
  void Failed(const Status& status);  // holds mu_
  // Takes the master for gone if it has been silent too long; holds mu_.
  void CheckMaster(std::chrono::steady_clock::time_point now);
  // Tells the master, once, that this rank has stopped sending (after its shutdown).
  Status Acknowledge();

  transport::Transport* net_;
  RenderEngine* engine_;
  PeerBlocks* peers_;
  std::thread receiver_;
  mutable std::mutex mu_;
  std::condition_variable changed_;
  bool stop_ = false;
  RemoteTiles* tiles_ = nullptr;  // the frame being rendered, if any
  bool shut_down_ = false;        // the master's shutdown has arrived
  uint32_t shutdown_reason_ = 0;
  bool acknowledged_ = false;
  Status error_;                  // a failure on the receiving side
  const NodeFaults faults_;
  const std::chrono::milliseconds master_lost_after_;
  std::chrono::steady_clock::time_point last_from_master_;
  bool heard_master_ = false;
  bool master_lost_ = false;
  bool master_interrupted_ = false;  // its beats say it was interrupted and is writing
  std::atomic<int64_t> tiles_given_{0};
};

}  // namespace raystack::slave
