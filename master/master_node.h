#pragma once
// The master's side of a distributed frame (rank 0): hands out tiles on request, merges the
// slaves' pixel batches into the film as they arrive, and gathers each slave's figures. It
// sees the slaves only through a Transport (MPI, or ranks as threads in one process).

#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <mutex>
#include <vector>

#include "common/base/status.h"
#include "common/render/film.h"
#include "common/render/tiles.h"
#include "common/transport/transport.h"
#include "common/wire/message.h"

namespace raystack::master {

struct SlaveFigures {
  int rank = 0;
  wire::FrameDone done{};  // as the slave reported it
  uint64_t bytes_received = 0;  // by the master from this slave (pixel batches and the rest)
  uint64_t bytes_sent = 0;      // by the master to this slave
  uint64_t pixel_bytes = 0;     // the pixel stream's share of bytes_received
};

struct FrameFigures {
  std::vector<SlaveFigures> slaves;  // by slave, rank 1 first
  double seconds = 0;                // the frame on the master's clock
  // Thesis definitions over the slaves' render times.
  double imbalance() const;  // 1 - mean / max
};

class MasterNode {
 public:
  explicit MasterNode(transport::Transport* net) : net_(net) {}

  // Runs frame `frame` until every slave has reported it done: tiles from `tiles` (in the
  // order they should be rendered), samples merged into `film`. `on_progress` is called from
  // time to time with the samples merged so far. A slave's error, or a malformed message,
  // ends the frame with an error naming the rank.
  Status RunFrame(uint32_t frame, std::vector<render::Tile> tiles, render::Film* film,
                  const std::function<void()>& on_progress, FrameFigures* figures);
  // Tells every slave the job is over (reason 0) or failed (1), then reads (and drops) what
  // they still send until each has acknowledged: a slave blocked sending a pixel batch must be
  // able to finish before every rank ends. False if some slave did not answer within `timeout`.
  bool Shutdown(uint32_t reason, std::chrono::milliseconds timeout = std::chrono::seconds(30));
  // The tiles handed out so far in the current (or last) frame, per slave (index = rank - 1),
  // in the order given. Thread-safe: the live preview reads it while RunFrame runs.
  std::vector<std::vector<render::Tile>> TilesAssigned() const;

 private:
  Status Send(int to, const std::vector<uint8_t>& bytes, FrameFigures* figures);
  transport::Transport* net_;
  // Messages for a later frame that arrived early (a fast slave's first requests).
  std::deque<transport::Envelope> early_;
  mutable std::mutex assigned_mu_;
  std::vector<std::vector<render::Tile>> assigned_;  // guarded by assigned_mu_
};

}  // namespace raystack::master
