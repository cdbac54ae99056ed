#pragma once
// Where ray threads get their next image tile: in one process, the frame's tiles in order; in
// a distributed run, the master's assignments. One virtual call per tile.

#include <atomic>
#include <cstdint>
#include <mutex>
#include <vector>

#include "common/render/frame_plan.h"
#include "common/render/tiles.h"

namespace raystack::slave {

using render::Tile;

class TileSource {
 public:
  virtual ~TileSource() = default;
  // The next tile for ray thread `thread`, false when the frame has no more. Thread-safe.
  virtual bool Next(uint32_t thread, Tile* tile) = 0;
  // Whether Next(thread) would answer at once. A source whose answers come from afar may make
  // Next wait (the master holds a request back while a lost slave's tiles may still come back),
  // so a thread that still holds rays asks with Ahead() and takes the tile once it is Ready.
  virtual bool Ready(uint32_t /*thread*/) const { return true; }
  // Ray thread `thread` will soon ask for its next tile (it has done the --tile-ahead share of
  // its current one): a source that must fetch tiles from afar starts now.
  virtual void Ahead(uint32_t /*thread*/) {}
  // The frame failed on this node (a damaged block, a read error): a thread waiting in Next
  // gives up (false). A remote source may hold a request back until every tile given out is
  // finished, and this node's never will be: without this it would wait forever.
  virtual void Abort() {}
};

// The whole frame's tiles once each, in Hilbert order (common/render/tiles.h), to whichever
// thread asks next: the simplest source, which the engine's tests drive it with (a render's
// tiles come from its frame plan: PlanTileSource).
class GridTileSource final : public TileSource {
 public:
  GridTileSource(int width, int height, int size)
      : tiles_(render::HilbertTiles(width, height, size)) {}
  bool Next(uint32_t, Tile* tile) override {
    const size_t i = next_.fetch_add(1);
    if (i >= tiles_.size()) return false;
    *tile = tiles_[i];
    return true;
  }

 private:
  std::vector<Tile> tiles_;
  std::atomic<size_t> next_{0};
};

// A progressive frame in one process: the plan's sweeps one after the other, each tile to
// whichever thread asks next, until the plan is done or Stop is called (a stop rule: the
// tiles already handed out still finish).
class PlanTileSource final : public TileSource {
 public:
  explicit PlanTileSource(const render::FramePlan& plan) : plan_(plan) {}
  bool Next(uint32_t, Tile* tile) override {
    std::lock_guard lock(mu_);
    while (!stopped_ && sweep_ < plan_.sweeps.size()) {
      if (!made_) {  // the sweep's tiles, made as it starts (the plan holds none)
        tiles_ = plan_.Tiles(sweep_);
        made_ = true;
      }
      if (next_ < tiles_.size()) {
        *tile = tiles_[next_++];
        return true;
      }
      ++sweep_;
      next_ = 0;
      made_ = false;
    }
    return false;
  }
  // No more tiles from now on (thread-safe).
  void Stop() {
    std::lock_guard lock(mu_);
    stopped_ = true;
  }

 private:
  const render::FramePlan& plan_;
  std::mutex mu_;
  size_t sweep_ = 0, next_ = 0;
  std::vector<Tile> tiles_;  // sweep_'s
  bool made_ = false;
  bool stopped_ = false;
};

}  // namespace raystack::slave
