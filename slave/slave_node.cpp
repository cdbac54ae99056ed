#include "slave/slave_node.h"

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <csignal>
#include <cstdio>
#include <deque>
#include <mutex>
#include <optional>
#include <thread>
#include <vector>

#include <sys/prctl.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include "common/base/interrupt.h"
#include "common/base/log.h"
#include "common/base/thread_cpu.h"
#include "common/base/thread_name.h"
#include "common/wire/message.h"
#include "slave/peer_blocks.h"

namespace raystack::slave {
namespace {

// Every thread of this process stops (SIGSTOP), as on a stalled node, and goes on after
// `seconds`: a child, which does only what is safe after fork in a threaded process, sends
// the SIGCONT.
void StopWholeProcess(double seconds) {
  const pid_t self = getpid();
  const pid_t child = fork();
  if (child == 0) {
    // Ends with the stopped process if that is killed (the job ended by force): it would
    // otherwise outlive it and signal whatever process takes its id.
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != self) _exit(0);
    timespec t{static_cast<time_t>(seconds),
               static_cast<long>((seconds - static_cast<double>(static_cast<time_t>(seconds))) * 1e9)};
    while (nanosleep(&t, &t) != 0) {
    }
    kill(self, SIGCONT);
    _exit(0);
  }
  if (child < 0) return;  // no stall then; the test that asked for it fails visibly
  kill(self, SIGSTOP);
  waitpid(child, nullptr, 0);
}

}  // namespace

// Tiles from the master: one slot per ray thread, holding up to kAhead tiles in reserve, asked
// for or come (or the news that there are no more). The receiving thread fills slots; ray
// threads take from them. Two in reserve, not one: a 32x32 tile takes a few ms, about the
// master's round trip while it merges the others' pixels, so with one the thread waited for
// its next tile (a fifth of a slave's frame with one slave, more with eight).
class RemoteTiles final : public TileSource {
 public:
  RemoteTiles(transport::Transport* net, uint32_t frame, int threads, int width, int height,
              std::atomic<int64_t>* given, const NodeFaults& faults)
      : net_(net), frame_(frame), width_(width), height_(height),
        slots_(static_cast<size_t>(threads)), given_(given), faults_(faults) {}

  bool Next(uint32_t thread, Tile* tile) override {
    Slot& s = slots_[thread];
    std::unique_lock lock(mu_);
    if (s.tiles.empty() && s.requested == 0) Request(thread, &s, &lock);
    // Not over while an answer is still to come: it would reach the next frame's slots.
    if (s.tiles.empty() && !Over(s) && !failed_) {
      transport::AnswerWait waiting(net_);
      cv_.wait(lock, [&] { return !s.tiles.empty() || Over(s) || failed_; });
    }
    if (s.tiles.empty()) return false;
    *tile = s.tiles.front();
    s.tiles.pop_front();
    if (tiles_++ == 0) first_tile_ = std::chrono::steady_clock::now();
    const int64_t given = given_->fetch_add(1) + 1;
    if (given == faults_.kill_after_tiles) {  // fault injection: die as kill -9 does
      LOG_WARNING("slave", "rank %d: killing itself at its tile %lld (--fault-kill-after-tiles)",
                  net_->rank(), static_cast<long long>(given));
      std::raise(SIGKILL);
    }
    if (given == faults_.stall_after_tiles) {
      LOG_WARNING("slave", "rank %d: stopping for %.1f s at its tile %lld (--fault-stall-after-tiles)",
                  net_->rank(), faults_.stall_seconds, static_cast<long long>(given));
      StopWholeProcess(faults_.stall_seconds);
    }
    return true;
  }

  bool Ready(uint32_t thread) const override {
    const Slot& s = slots_[thread];
    std::lock_guard lock(mu_);
    return !s.tiles.empty() || Over(s) || failed_;
  }

  // The next tiles, fetched while this one renders (at --tile-ahead of it).
  void Ahead(uint32_t thread) override {
    Slot& s = slots_[thread];
    std::unique_lock lock(mu_);
    TopUp(thread, &s, &lock);
  }

  // From the receiving thread.
  Status Deliver(const wire::TileAssign& a) {
    std::lock_guard lock(mu_);
    if (a.frame != frame_ || a.thread >= slots_.size())
      return Status::Error(StrFormat("the master assigned a tile of frame %u to thread %u "
                                     "(this is frame %u with %zu threads)",
                                     a.frame, a.thread, frame_, slots_.size()));
    Slot& s = slots_[a.thread];
    if (s.requested == 0)
      return Status::Error(StrFormat("the master assigned thread %u a tile it did not ask for",
                                     a.thread));
    --s.requested;
    if (a.none) {
      s.exhausted = true;
    } else {
      // Inside the image, so a tile's pixels are the image's and their count is bounded.
      if (a.x0 < 0 || a.y0 < 0 || a.x1 <= a.x0 || a.y1 <= a.y0 || a.x1 > width_ || a.y1 > height_)
        return Status::Error(StrFormat("the master assigned the tile [%d,%d)x[%d,%d), empty or "
                                       "outside the %dx%d image", a.x0, a.x1, a.y0, a.y1, width_,
                                       height_));
      if (a.sample_end != 0 &&
          (a.sample_end <= a.sample_begin || a.sample_end - a.sample_begin > kMaxTileSampleRange))
        return Status::Error(StrFormat("the master assigned the samples [%u, %u) of a tile (at "
                                       "most %u at once)", a.sample_begin, a.sample_end,
                                       kMaxTileSampleRange));
      const uint16_t rank_end = a.rank_end == 0 ? 256 : a.rank_end;
      if (a.rank_begin >= rank_end || rank_end > 256)
        return Status::Error(StrFormat("the master assigned the pixel ranks [%u, %u) of a tile",
                                       a.rank_begin, a.rank_end));
      s.tiles.push_back({a.x0, a.y0, a.x1, a.y1, a.sample_begin, a.sample_end, a.rank_begin, rank_end});
    }
    cv_.notify_all();
    return OkStatus();
  }

  void Abort() override {
    std::lock_guard lock(mu_);
    failed_ = true;
    cv_.notify_all();
  }

  uint64_t tiles() const { return tiles_.load(); }
  // When the first tile was handed to a ray thread (none: the epoch).
  std::chrono::steady_clock::time_point first_tile() const {
    std::lock_guard lock(mu_);
    return first_tile_;
  }

 private:
  static constexpr uint32_t kMaxTileSampleRange = 1 << 20;
  struct Slot {
    std::deque<Tile> tiles;  // come, not taken yet
    uint32_t requested = 0;  // asked for, not come yet
    bool exhausted = false;
  };
  static constexpr uint32_t kAhead = 2;
  // No more tiles, and every request answered.
  static bool Over(const Slot& s) { return s.exhausted && s.requested == 0; }
  void TopUp(uint32_t thread, Slot* s, std::unique_lock<std::mutex>* lock) {
    while (!s->exhausted && !failed_ && s->requested + s->tiles.size() < kAhead)
      Request(thread, s, lock);
  }
  // Counted as asked for under the lock, sent without it: the receiving thread takes the lock
  // to deliver tiles, and must never wait for a send (it also sends the heartbeats).
  void Request(uint32_t thread, Slot* s, std::unique_lock<std::mutex>* lock) {
    if (s->exhausted || failed_) return;
    ++s->requested;
    lock->unlock();
    const Status st =
        net_->Send(0, wire::Encode(static_cast<uint32_t>(net_->rank()), wire::TileRequest{frame_, thread}));
    lock->lock();
    if (!st.ok()) {
      LOG_ERROR("slave", "%s", st.message().c_str());
      failed_ = true;
      cv_.notify_all();
    }
  }

  transport::Transport* net_;
  const uint32_t frame_;
  const int width_, height_;  // the image's: tiles must lie inside it
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::vector<Slot> slots_;
  bool failed_ = false;
  std::atomic<uint64_t> tiles_{0};
  std::chrono::steady_clock::time_point first_tile_{};  // (under mu_)
  std::atomic<int64_t>* given_;  // tiles given to this node in the job
  const NodeFaults faults_;
};

namespace {

// Samples to the master, a batch per call (ray threads call it concurrently; Post is
// thread-safe). Posted, not sent: with Send a ray thread waited for the master to take each
// batch (a batch is larger than MPI's eager limit), which was half of a slave's frame time
// under mpirun even with one slave. The backlog is bounded: past kMaxBacklogBytes not yet
// taken, a ray thread waits for the master as it did before.
class RemoteSink final : public render::SampleSink {
 public:
  RemoteSink(transport::Transport* net, uint32_t frame) : net_(net), frame_(frame) {}
  void Consume(std::span<const render::SampleResult> batch, uint64_t rays) override {
    for (size_t i = 0; i < batch.size(); i += wire::kMaxBatchSamples) {
      const size_t n = std::min<size_t>(wire::kMaxBatchSamples, batch.size() - i);
      if (net_->posted_bytes() > kMaxBacklogBytes) {
        transport::AnswerWait waiting(net_);  // the batches out go at the quickest pace
        while (net_->posted_bytes() > kMaxBacklogBytes)
          std::this_thread::sleep_for(std::chrono::microseconds(200));
      }
      const Status s = net_->Post(0, wire::EncodePixelBatch(static_cast<uint32_t>(net_->rank()),
                                                            frame_, batch.subspan(i, n),
                                                            i == 0 ? rays : 0));
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
  static constexpr uint64_t kMaxBacklogBytes = 16 << 20;
  mutable std::mutex mu_;
  Status error_;
};

}  // namespace

SlaveNode::SlaveNode(transport::Transport* net, RenderEngine* engine, PeerBlocks* peers,
                     NodeFaults faults, std::chrono::milliseconds master_lost_after)
    : net_(net), engine_(engine), peers_(peers), faults_(faults),
      master_lost_after_(master_lost_after), last_from_master_(std::chrono::steady_clock::now()) {
  HoldInterrupts(true);  // while this node runs, a signal is the master's to act on first
  // The receiving thread looks for messages at its quickest only while a thread here waits
  // for one (a tile, a block from a peer, the last pixels out); otherwise every kIdlePause:
  // each look costs the capped CPU the rays need (tools/bench/RESULTS.md).
  net_->SetIdlePause(kIdlePause);
  receiver_ = std::thread([this] {
    SetThreadName("rs-receive");
    ReceiveLoop();
  });
}

SlaveNode::~SlaveNode() {
  HoldInterrupts(false);
  {
    std::lock_guard lock(mu_);
    stop_ = true;
  }
  receiver_.join();
  if (peers_) peers_->Stop();
}

void SlaveNode::Failed(const Status& status) {  // holds mu_
  if (error_.ok()) error_ = status;
  if (tiles_) tiles_->Abort();
  changed_.notify_all();
}

bool SlaveNode::master_lost() const {
  std::lock_guard lock(mu_);
  return master_lost_;
}

void SlaveNode::CheckMaster(std::chrono::steady_clock::time_point now) {
  if (master_lost_after_.count() == 0 || master_lost_ || shut_down_) return;
  const auto allowed = heard_master_ ? master_lost_after_ : master_lost_after_ + kMasterFirstWordGrace;
  if (now - last_from_master_ < allowed) return;
  master_lost_ = true;
  net_->NoteRankDied(0);  // nothing may wait for it any more, MPI_Finalize included
  Failed(Status::Error(StrFormat(
      "the master (rank 0) has said nothing for %.0f s: it is gone, or this host is cut off "
      "from it; this rank ends (its pixels are the master's to lose or keep)",
      std::chrono::duration<double>(now - last_from_master_).count())));
  changed_.notify_all();
}

void SlaveNode::ReceiveLoop() {
  uint32_t beats = 0;
  auto last_beat = std::chrono::steady_clock::now() - wire::kHeartbeatInterval;
  auto last_turn = std::chrono::steady_clock::now();
  std::optional<std::chrono::steady_clock::time_point> interrupted;  // when first seen
  for (;;) {
    {
      std::lock_guard lock(mu_);
      if (stop_) return;
    }
    // Alive, whatever the ray threads are doing (a long block read, a big tile): the master
    // drops a slave it does not hear from.
    if (std::chrono::steady_clock::now() - last_beat >= wire::kHeartbeatInterval) {
      last_beat = std::chrono::steady_clock::now();
      // Posted: a send to a master that vanished might never complete, and this thread is the
      // one that would notice (CheckMaster). A failure comes back from the next Receive.
      const Status s = net_->Post(0, wire::Encode(static_cast<uint32_t>(net_->rank()),
                                                  wire::Heartbeat{beats++, 0}));
      if (!s.ok()) {  // (also another posted send's failure, found while posting this one)
        std::lock_guard lock(mu_);
        Failed(s);
      }
    }
    Expected<std::optional<transport::Envelope>> got = net_->Receive(std::chrono::milliseconds(20));
    std::lock_guard lock(mu_);
    const auto now = std::chrono::steady_clock::now();
    // This thread was away (the process stopped, the job suspended, the machine paused): the
    // master's words are still queued, so that time counts as heard, and the queue is read
    // before the master is judged (as the master does with its slaves).
    if (now - last_turn > master_lost_after_ / 2) last_from_master_ += now - last_turn;
    last_turn = now;
    // SIGINT or SIGTERM (held: common/base/interrupt.h): the master, which gets it too, writes
    // its frame and ends the job (its beats say it is at it: this rank waits for that end,
    // however long the write takes); a signal meant for this rank alone (the master's beats do
    // not say so) ends it a moment later.
    if (const int signal = InterruptSignal(); signal != 0 && !shut_down_ && !master_interrupted_) {
      if (!interrupted) interrupted = now;
      if (now - *interrupted > kInterruptGrace) {
        std::fprintf(stderr, "raystack render (rank %d): interrupted (%s), and the master did not "
                     "end the job: ending\n", net_->rank(), InterruptName(signal));
        std::fflush(nullptr);
        std::_Exit(128 + signal);
      }
    }
    if (peers_) {  // a read for a peer failed (on the server thread, or below)
      if (Status s = peers_->TakeServeFailure(); !s.ok()) Failed(s);
    }
    if (!got.ok()) {
      Failed(got.status());
      continue;
    }
    if (!got->has_value()) {  // nothing queued: the master's silence is real
      CheckMaster(now);
      continue;
    }
    const int from = (*got)->from;
    if (from == 0) {
      last_from_master_ = now;
      heard_master_ = true;
    }
    const Expected<wire::Message> m = wire::Decode((*got)->bytes, from);
    if (!m.ok() && from == 0) {
      // A master of another build (or a broken one): this rank cannot follow it, nor read its
      // shutdown, so it ends now rather than wait for one.
      master_lost_ = true;
      net_->NoteRankDied(0);
      Failed(m.status());
      continue;
    }
    if (!m.ok()) {
      Failed(m.status());
      continue;
    }
    const wire::MessageType type = m->type();
    if (from == 0 && type == wire::MessageType::kTileAssign) {
      // Between frames, only a late answer to a request of a frame that failed can come:
      // nothing waits for it any more.
      if (tiles_) {
        const Status s = tiles_->Deliver(m->tile_assign());
        if (!s.ok()) Failed(s);
      }
    } else if (from == 0 && type == wire::MessageType::kShutdown) {
      shut_down_ = true;
      shutdown_reason_ = m->shutdown().reason;
      if (m->shutdown().flags & wire::kShutdownRankDied) net_->NoteRankDied(-1);
      if (tiles_) tiles_->Abort();  // ray threads waiting for a tile give up
      if (peers_) peers_->Stop();
      changed_.notify_all();
    } else if (from == 0 && type == wire::MessageType::kHeartbeat) {
      // The master is alive (noted above), and perhaps writing its frame after a signal.
      if (m->heartbeat().flags & wire::kHeartbeatInterrupted) master_interrupted_ = true;
    } else if (from == 0 && type == wire::MessageType::kRankLost) {
      const wire::RankLost lost = m->rank_lost();
      if (lost.rank == 0 || lost.rank >= static_cast<uint32_t>(net_->size())) {
        Failed(Status::Error(
            StrFormat("the master reports rank %u lost, which is not a slave", lost.rank)));
      } else {
        // Fetches from it first read from disk instead; only then do sends to it fail (a
        // fetch whose request fails before its owner is marked lost would fail the load).
        if (peers_) peers_->OwnerLost(static_cast<int>(lost.rank));
        if (lost.died) net_->NoteRankDied(static_cast<int>(lost.rank));
      }
    } else if (from > 0 && peers_ && type == wire::MessageType::kBlockRequest) {
      const Status s = peers_->OnRequest(from, m.value());
      if (!s.ok()) Failed(s);
    } else if (from > 0 && peers_ && type == wire::MessageType::kBlockData) {
      const Status s = peers_->OnData(from, m.value(), &(*got)->bytes);
      if (!s.ok()) Failed(s);
    } else {
      Failed(Status::Error(StrFormat("rank %d sent this slave a %s it has no use for", from,
                                     wire::MessageTypeName(type))));
    }
  }
}

Status SlaveNode::RunFrame(uint32_t frame, const render::Scene& scene,
                           const render::MaterialTable& materials, const render::Camera& camera,
                           RenderStats* stats) {
  const uint32_t me = static_cast<uint32_t>(net_->rank());
  RemoteTiles tiles(net_, frame, engine_->options().threads, camera.width(), camera.height(),
                    &tiles_given_, faults_);
  RemoteSink sink(net_, frame);
  {
    std::unique_lock lock(mu_);
    if (shut_down_) {
      lock.unlock();
      (void)Acknowledge();  // a failed send: the master times out on this rank
      return Status::Error("the master ended the job");
    }
    tiles_ = &tiles;
    if (!error_.ok()) tiles.Abort();
  }
  const uint64_t from_peers = peers_ ? peers_->bytes_from_peers() : 0;
  const uint64_t to_peers = peers_ ? peers_->bytes_to_peers() : 0;
  const uint64_t fetches = peers_ ? peers_->fetches() : 0;
  const double fetch_wait = peers_ ? peers_->fetch_wait_seconds() : 0;
  const uint64_t fetch_runs = peers_ ? peers_->runs_fetched() : 0;
  const double cpu_before = ProcessCpuSeconds();
  const auto began = std::chrono::steady_clock::now();
  Status status = engine_->RenderFrame(scene, materials, camera, tiles, sink, stats);
  const double process_cpu = ProcessCpuSeconds() - cpu_before;
  const auto rendered = std::chrono::steady_clock::now();
  if (status.ok()) FlushPixels();  // after the figures: they are the render's
  bool shut_down;
  {
    std::lock_guard lock(mu_);
    tiles_ = nullptr;
    if (!error_.ok()) status = error_;  // the receiving side's failure came first
    shut_down = shut_down_;
  }
  if (status.ok()) status = sink.error();
  if (shut_down) {  // the master ended the job: this rank sends nothing more but the ack
    (void)Acknowledge();
    return status.ok() ? Status::Error("the master ended the job during the frame") : status;
  }
  if (!status.ok()) {
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
  // From its first tile, not from the frame's start: the wait for the first tile is the
  // master's (it hands tiles out one at a time), and counting it would make every slave's time
  // look like the longest, hiding imbalance. No tile: it worked 0 s.
  d.seconds = tiles.tiles() == 0
                  ? 0.0
                  : std::chrono::duration<double>(rendered - tiles.first_tile()).count();
  d.busy_seconds = stats->ray_busy_seconds;
  d.tile_wait_seconds = stats->ray_tile_wait_seconds;
  d.block_wait_seconds = stats->ray_idle_seconds;
  d.engine_seconds = std::chrono::duration<double>(rendered - began).count();
  d.ray_cpu_seconds = stats->ray_cpu_seconds;
  d.loader_cpu_seconds = stats->loader_cpu_seconds;
  d.process_cpu_seconds = process_cpu;
  d.flags = stats->direct_reads ? wire::kFrameDoneDirectReads : 0;
  static_assert(kRayTypeCount == 4);
  for (int t = 0; t < 4; ++t) d.rays_by_type[t] = stats->rays[static_cast<size_t>(t)];
  d.reads = stats->reads;
  d.block_visits = stats->block_visits;
  d.cache_hit_rate = stats->cache_hit_rate;
  d.loader_busy_seconds = stats->loader_busy_seconds;
  d.cache_budget_bytes = stats->cache_budget_bytes;
  d.cache_peak_bytes = stats->cache_peak_bytes;
  d.evictions = stats->evictions;
  d.peak_stack_bytes = stats->peak_stack_bytes;
  d.peak_stack_rays = stats->peak_stack_rays;
  d.peak_rss_bytes = stats->peak_rss_bytes;
  if (peers_) {
    d.bytes_from_peers = peers_->bytes_from_peers() - from_peers;
    d.bytes_to_peers = peers_->bytes_to_peers() - to_peers;
    d.fetches = peers_->fetches() - fetches;
    d.fetch_wait_seconds = peers_->fetch_wait_seconds() - fetch_wait;
    d.fetch_runs = peers_->runs_fetched() - fetch_runs;
  }
  return net_->Send(0, wire::Encode(me, d));
}

void SlaveNode::FlushPixels() {
  // The master ends the frame once it has every pixel: the last batches go out at the quickest
  // pace, not at the idle one. Only a matter of pace: after a while (a receiver that takes
  // nothing) they go on at the idle one.
  transport::AnswerWait waiting(net_);
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(1);
  while (net_->posted_bytes() > 0 && std::chrono::steady_clock::now() < give_up) {
    {
      std::lock_guard lock(mu_);
      if (shut_down_ || !error_.ok()) return;
    }
    std::this_thread::sleep_for(std::chrono::microseconds(100));
  }
}

Expected<uint32_t> SlaveNode::WaitForShutdown(std::chrono::milliseconds timeout) {
  // Only the shutdown ends the wait: the master drains its slaves until each acknowledges it,
  // failed ones too (a failure seen after the frame changes nothing about the end).
  std::unique_lock lock(mu_);
  if (!changed_.wait_for(lock, timeout, [&] { return shut_down_ || master_lost_; }))
    return Status::Error("the master did not end the job in time");
  if (!shut_down_) return error_;  // the master is gone: no one to acknowledge
  const uint32_t reason = shutdown_reason_;
  lock.unlock();
  RAYSTACK_RETURN_IF_ERROR(Acknowledge());
  return reason;
}

Status SlaveNode::Acknowledge() {
  {
    std::lock_guard lock(mu_);
    if (acknowledged_) return OkStatus();
    acknowledged_ = true;
  }
  return net_->Send(0, wire::Encode(static_cast<uint32_t>(net_->rank()), wire::Shutdown{0, 0}));
}

}  // namespace raystack::slave
