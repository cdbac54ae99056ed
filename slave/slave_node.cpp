#include "slave/slave_node.h"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <vector>

#include "common/base/log.h"
#include "common/wire/message.h"

namespace raystack::slave {
namespace {

// Tiles from the master: one slot per ray thread, holding the tile in reserve (or the news
// that there are no more). The receiving thread fills slots; ray threads take from them.
class RemoteTiles final : public TileSource {
 public:
  RemoteTiles(transport::Transport* net, uint32_t frame, int threads)
      : net_(net), frame_(frame), slots_(static_cast<size_t>(threads)) {}

  bool Next(uint32_t thread, Tile* tile) override {
    Slot& s = slots_[thread];
    std::unique_lock lock(mu_);
    if (!s.requested && !s.has_tile && !s.exhausted) Request(thread, &s);
    cv_.wait(lock, [&] { return s.has_tile || s.exhausted || failed_; });
    if (!s.has_tile) return false;
    *tile = s.tile;
    s.has_tile = false;
    ++tiles_;
    return true;
  }

  // The next tile, fetched while this one renders (at --tile-ahead of it).
  void Ahead(uint32_t thread) override {
    Slot& s = slots_[thread];
    std::lock_guard lock(mu_);
    if (!s.requested && !s.has_tile && !s.exhausted) Request(thread, &s);
  }

  // From the receiving thread.
  Status Deliver(const wire::TileAssign& a) {
    std::lock_guard lock(mu_);
    if (a.frame != frame_ || a.thread >= slots_.size())
      return Status::Error(StrFormat("the master assigned a tile of frame %u to thread %u "
                                     "(this is frame %u with %zu threads)",
                                     a.frame, a.thread, frame_, slots_.size()));
    Slot& s = slots_[a.thread];
    if (!s.requested)
      return Status::Error(StrFormat("the master assigned thread %u a tile it did not ask for",
                                     a.thread));
    s.requested = false;
    if (a.none) {
      s.exhausted = true;
    } else {
      if (a.x0 < 0 || a.y0 < 0 || a.x1 <= a.x0 || a.y1 <= a.y0)
        return Status::Error(StrFormat("the master assigned an empty tile [%d,%d)x[%d,%d)",
                                       a.x0, a.x1, a.y0, a.y1));
      s.tile = {a.x0, a.y0, a.x1, a.y1};
      s.has_tile = true;
    }
    cv_.notify_all();
    return OkStatus();
  }

  void Fail() {
    std::lock_guard lock(mu_);
    failed_ = true;
    cv_.notify_all();
  }

  uint64_t tiles() const { return tiles_.load(); }

 private:
  struct Slot {
    Tile tile;
    bool has_tile = false, requested = false, exhausted = false;
  };
  void Request(uint32_t thread, Slot* s) {  // holds mu_
    if (s->exhausted || failed_) return;
    s->requested = true;
    const Status st =
        net_->Send(0, wire::Encode(static_cast<uint32_t>(net_->rank()), wire::TileRequest{frame_, thread}));
    if (!st.ok()) {
      LOG_ERROR("slave", "%s", st.message().c_str());
      failed_ = true;
    }
  }

  transport::Transport* net_;
  const uint32_t frame_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::vector<Slot> slots_;
  bool failed_ = false;
  std::atomic<uint64_t> tiles_{0};
};

// Samples to the master, a batch per call (ray threads call it concurrently; Send is
// thread-safe).
class RemoteSink final : public render::SampleSink {
 public:
  RemoteSink(transport::Transport* net, uint32_t frame) : net_(net), frame_(frame) {}
  void Consume(std::span<const render::SampleResult> batch) override {
    for (size_t i = 0; i < batch.size(); i += wire::kMaxBatchSamples) {
      const size_t n = std::min<size_t>(wire::kMaxBatchSamples, batch.size() - i);
      const Status s = net_->Send(0, wire::EncodePixelBatch(static_cast<uint32_t>(net_->rank()),
                                                            frame_, batch.subspan(i, n)));
      if (!s.ok()) {
        std::lock_guard lock(mu_);
        if (error_.ok()) error_ = s;
      }
    }
  }
  Status error() const {
    std::lock_guard lock(mu_);
    return error_;
  }

 private:
  transport::Transport* net_;
  const uint32_t frame_;
  mutable std::mutex mu_;
  Status error_;
};

}  // namespace

Status SlaveNode::RunFrame(uint32_t frame, const render::Scene& scene,
                           const render::MaterialTable& materials, const render::Camera& camera,
                           RenderStats* stats) {
  const uint32_t me = static_cast<uint32_t>(net_->rank());
  RemoteTiles tiles(net_, frame, engine_->options().threads);
  RemoteSink sink(net_, frame);
  std::atomic<bool> rendered{false};
  Status render_status;
  std::thread render([&] {
    render_status = engine_->RenderFrame(scene, materials, camera, tiles, sink, stats);
    rendered.store(true);
  });
  // This thread receives: tile assignments for the ray threads, or the master's shutdown.
  Status status;
  while (!rendered.load() && status.ok()) {
    Expected<std::optional<transport::Envelope>> got = net_->Receive(std::chrono::milliseconds(20));
    if (!got.ok()) {
      status = got.status();
      break;
    }
    if (!got->has_value()) continue;
    const Expected<wire::Message> m = wire::Decode((*got)->bytes, (*got)->from);
    if (!m.ok()) {
      status = m.status();
    } else if ((*got)->from != 0) {
      status = Status::Error(StrFormat("rank %d sent a %s to a slave", (*got)->from,
                                       wire::MessageTypeName(m->type())));
    } else if (m->type() == wire::MessageType::kTileAssign) {
      status = tiles.Deliver(m->tile_assign());
    } else if (m->type() == wire::MessageType::kShutdown) {
      shut_down_ = true;
      status = Status::Error("the master ended the job during the frame");
    } else {
      status = Status::Error(StrFormat("the master sent a %s during a frame",
                                       wire::MessageTypeName(m->type())));
    }
  }
  if (!status.ok()) tiles.Fail();  // ray threads waiting for a tile give up
  render.join();
  if (status.ok()) status = render_status;
  if (status.ok()) status = sink.error();
  if (!status.ok()) {
    if (shut_down_) {  // the master ended the job: nothing more will be sent from here
      (void)net_->Send(0, wire::Encode(me, wire::Shutdown{1, 0}));
      return status;
    }
    const Status told = net_->Send(0, wire::EncodeError(me, status.message()));
    if (!told.ok()) LOG_ERROR("slave", "%s", told.message().c_str());
    return status;
  }
  wire::FrameDone d{};
  d.frame = frame;
  d.ray_threads = static_cast<uint32_t>(engine_->options().threads);
  d.samples = stats->samples;
  d.rays = stats->rays_total;
  d.tiles = tiles.tiles();
  d.blocks_loaded = stats->blocks_loaded;
  d.blocks_distinct = stats->blocks_distinct;
  d.bytes_read = stats->bytes_read;
  d.seconds = stats->seconds;
  return net_->Send(0, wire::Encode(me, d));
}

Expected<uint32_t> SlaveNode::WaitForShutdown(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    Expected<std::optional<transport::Envelope>> got = net_->Receive(std::chrono::milliseconds(200));
    if (!got.ok()) return got.status();
    if (!got->has_value()) {
      if (std::chrono::steady_clock::now() > deadline)
        return Status::Error("the master did not end the job in time");
      continue;
    }
    const Expected<wire::Message> m = wire::Decode((*got)->bytes, (*got)->from);
    if (!m.ok()) return m.status();
    if (m->type() == wire::MessageType::kShutdown) {
      shut_down_ = true;
      // The acknowledgement: this rank sends nothing more.
      RAYSTACK_RETURN_IF_ERROR(net_->Send(0, wire::Encode(static_cast<uint32_t>(net_->rank()),
                                                          wire::Shutdown{0, 0})));
      return m->shutdown().reason;
    }
    if (m->type() == wire::MessageType::kTileAssign) continue;  // a late answer to a failed frame
    return Status::Error(StrFormat("rank %d sent a %s after the last frame", (*got)->from,
                                   wire::MessageTypeName(m->type())));
  }
}

}  // namespace raystack::slave
