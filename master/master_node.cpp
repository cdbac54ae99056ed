#include "master/master_node.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <utility>

#include "common/base/check.h"
#include "common/base/interrupt.h"
#include "common/base/log.h"
#include "master/tile_ledger.h"
#include "master/tile_scheduler.h"

namespace raystack::master {

using Clock = std::chrono::steady_clock;

double FrameFigures::imbalance() const {
  double sum = 0, max = 0;
  size_t counted = 0;
  for (const SlaveFigures& s : slaves) {
    if (s.dropped) continue;
    sum += s.done.seconds;
    max = std::max(max, s.done.seconds);
    ++counted;
  }
  return max > 0 ? 1.0 - sum / static_cast<double>(counted) / max : 0.0;
}

double FrameFigures::utilisation() const {
  double busy = 0, offered = 0;
  for (const SlaveFigures& s : slaves) {
    if (s.dropped) continue;
    busy += s.done.busy_seconds;
    offered += static_cast<double>(s.done.ray_threads) * seconds;
  }
  return offered > 0 ? busy / offered : 0.0;
}

struct MasterNode::Frame {
  uint32_t number;
  render::Film* film;
  FrameFigures* figures;
  const render::FramePlan* plan;
  size_t sweep = 0;  // the current sweep; the next starts once every tile of this one is out
  std::unique_ptr<TileScheduler> scheduler;
  std::deque<render::Tile> returned;  // a dropped slave's unfinished tiles, handed out first
  bool stopped = false;               // a stop rule holds: no more tiles
  TileLedger ledger;
  std::vector<bool> done;  // by rank: reported done, or dropped
  int remaining = 0;       // slaves still rendering this frame
  // Requests held back while every tile is out but some are unfinished (rank, thread).
  std::deque<std::pair<int, uint32_t>> held;
  std::deque<transport::Envelope> later;  // for frames after this one
  std::vector<render::SampleResult> samples;
};

MasterNode::MasterNode(transport::Transport* net, MasterOptions options)
    : net_(net), options_(options), slaves_(static_cast<size_t>(net->size())) {
  last_check_ = Clock::now();
  for (SlaveState& s : slaves_) s.last_heard = last_check_;
  if (!options_.beat) return;
  beating_ = true;
  beater_ = std::thread([this] {
    for (uint32_t beat = 0;; ++beat) {
      // Sent, not posted: a posted send's failure would come back from the master's next
      // Receive and end the frame, where a beat that fails (a dying slave) only drops the beat.
      // A small send does not wait for its receiver (MPI's eager path); a slave taken for dead
      // gets none (a send to it would wait out the transport's grace).
      const uint32_t flags = InterruptSignal() != 0 ? wire::kHeartbeatInterrupted : 0u;
      for (int r = 1; r < net_->size(); ++r)
        if (!net_->dead(r)) (void)net_->Send(r, wire::Encode(0, wire::Heartbeat{beat, flags}));
      std::unique_lock lock(beat_mu_);
      if (beat_stop_.wait_for(lock, wire::kHeartbeatInterval, [this] { return !beating_; })) return;
    }
  });
}

MasterNode::~MasterNode() { StopBeating(); }

void MasterNode::StopBeating() {
  {
    std::lock_guard lock(beat_mu_);
    beating_ = false;
  }
  beat_stop_.notify_all();
  if (beater_.joinable()) beater_.join();
}

Status MasterNode::Send(int to, const std::vector<uint8_t>& bytes, FrameFigures* figures) {
  figures->slaves[static_cast<size_t>(to - 1)].bytes_sent += bytes.size();
  return net_->Send(to, bytes);
}

bool MasterNode::Shutdown(uint32_t reason, std::chrono::milliseconds timeout) {
  StopBeating();  // the slaves wait for the shutdown now, not for the master's word
  std::vector<bool> acknowledged(static_cast<size_t>(net_->size()), false);
  int waiting = 0;
  bool died = false;
  for (const SlaveState& s : slaves_) died = died || s.lost;
  for (int r = 1; r < net_->size(); ++r) {
    const SlaveState& slave = slaves_[static_cast<size_t>(r)];
    const Status s = net_->Send(
        r, wire::Encode(0, wire::Shutdown{reason, died ? wire::kShutdownRankDied : 0u}));
    // A lost slave may be dead: it is told, but nothing waits for its answer; nor for one
    // that cannot read this build's messages.
    if (s.ok() && !slave.lost && !slave.deaf) {
      ++waiting;
    } else if (!s.ok()) {
      LOG_WARNING("master", "%s", s.message().c_str());
    }
  }
  const auto deadline = Clock::now() + timeout;
  while (waiting > 0 && Clock::now() < deadline) {
    Expected<std::optional<transport::Envelope>> got = net_->Receive(std::chrono::milliseconds(100));
    if (!got.ok() || !got->has_value()) continue;  // (until the deadline)
    const Expected<wire::Message> m = wire::Decode((*got)->bytes, (*got)->from);
    const int from = (*got)->from;
    if (m.ok() && m->type() == wire::MessageType::kShutdown && from > 0 &&
        from < net_->size() && !acknowledged[static_cast<size_t>(from)] &&
        !slaves_[static_cast<size_t>(from)].lost) {
      acknowledged[static_cast<size_t>(from)] = true;
      --waiting;
    }
  }
  early_.clear();
  // Ranks that will not end with this one (MPI_Finalize would wait for them forever).
  bool all = true;
  for (int r = 1; r < net_->size(); ++r) {
    const SlaveState& slave = slaves_[static_cast<size_t>(r)];
    if (acknowledged[static_cast<size_t>(r)]) continue;
    if (slave.lost) {
      // Lost for its silence, it may be alive but frozen (a stopped process, a hung node):
      // mpirun would wait for it forever, even with the image written (an operator's job held
      // its allocation that way). Dead, ending by force costs nothing more.
      LOG_WARNING("master", "rank %d was lost and has not said it ended: the job is ended by force "
                  "once this rank is done (mpirun then prints an MPI_ABORT notice with "
                  "errorcode 0; what was written is complete)", r);
      net_->NoteRankWillNotEnd(r);
      continue;
    }
    all = false;
    LOG_WARNING("master", "rank %d %s: the job is ended by force", r,
                slave.deaf ? "cannot read this build's messages" : "did not acknowledge the end of the job");
    net_->NoteRankWillNotEnd(r);
  }
  return all;
}

void MasterNode::Abandon() {
  StopBeating();
  for (int r = 1; r < net_->size(); ++r)
    (void)net_->Send(r, wire::Encode(0, wire::Shutdown{1, wire::kShutdownRankDied}));
}

std::vector<std::vector<render::Tile>> MasterNode::TilesAssigned() const {
  std::lock_guard lock(assigned_mu_);
  return assigned_;
}

std::vector<std::string> MasterNode::SlavesDropped() const {
  std::lock_guard lock(assigned_mu_);
  return dropped_;
}

// The next tile for `rank`: a returned one first, then the current sweep's, then the next
// sweep's; false once a stop rule holds or every sweep is out.
bool MasterNode::NextTile(Frame* f, int rank, render::Tile* t) {
  if (f->stopped) return false;
  if (!f->returned.empty()) {
    *t = f->returned.front();
    f->returned.pop_front();
    return true;
  }
  while (f->scheduler) {
    size_t index;
    if (f->scheduler->Next(rank - 1, &index)) {
      *t = f->scheduler->tile(index);
      return true;
    }
    f->scheduler = ++f->sweep < f->plan->sweeps.size()
                       ? std::make_unique<TileScheduler>(f->plan->Tiles(f->sweep), net_->size() - 1)
                       : nullptr;
  }
  return false;
}

// Whether the frame still has samples to render (and may: no stop rule holds).
bool MasterNode::WorkLeft(const Frame& f) const {
  if (f.stopped) return false;
  if (!f.returned.empty() || f.ledger.unfinished() > 0) return true;
  if (f.scheduler && !f.scheduler->exhausted()) return true;
  for (size_t i = f.sweep + 1; i < f.plan->sweeps.size(); ++i)
    if (f.plan->sweeps[i].tile_count > 0) return true;
  return false;
}

Status MasterNode::Answer(Frame* f, int rank, uint32_t thread) {
  wire::TileAssign a{};
  a.frame = f->number;
  a.thread = thread;
  render::Tile t;
  if (NextTile(f, rank, &t)) {
    a.x0 = t.x0, a.y0 = t.y0, a.x1 = t.x1, a.y1 = t.y1;
    a.sample_begin = t.sample_begin, a.sample_end = t.sample_end;
    a.rank_begin = t.rank_begin, a.rank_end = t.rank_end;
    f->ledger.Assign(t, rank);
    std::lock_guard lock(assigned_mu_);
    // Its latest tiles only: a slave holds a few per ray thread (the current one and those
    // asked ahead), and the preview scans each listed tile's pixels on every refresh.
    std::vector<render::Tile>& mine = assigned_[static_cast<size_t>(rank - 1)];
    if (mine.size() >= kPreviewTilesPerSlave) mine.erase(mine.begin());
    mine.push_back(t);
  } else if (!f->stopped && f->ledger.unfinished() > 0) {
    f->held.emplace_back(rank, thread);  // a lost slave's tiles may still come back
    return OkStatus();
  } else {
    a.none = 1;
  }
  return Send(rank, wire::Encode(0, a), f->figures);
}

// Held requests get the tiles that came back, or, once every tile is finished, the news that
// there are no more.
Status MasterNode::AnswerHeldRequests(Frame* f) {
  while (!f->held.empty()) {
    const auto [rank, thread] = f->held.front();
    if (slaves_[static_cast<size_t>(rank)].dropped) {
      f->held.pop_front();
      continue;
    }
    size_t waiting = f->held.size();
    f->held.pop_front();
    RAYSTACK_RETURN_IF_ERROR(Answer(f, rank, thread));
    if (f->held.size() == waiting) return OkStatus();  // held again: nothing to give yet
  }
  return OkStatus();
}

Status MasterNode::Drop(Frame* f, int rank, bool lost, const std::string& why) {
  SlaveState& s = slaves_[static_cast<size_t>(rank)];
  s.dropped = true;
  s.lost = lost;
  if (lost) {
    net_->NoteRankDied(rank);
    // Silent is not always dead (a starved process, a stalled node): a rank that is still
    // alive must stop now, not wait for tiles this master no longer gives it, and must end
    // without waiting for the ranks taken for dead. A dead one never reads it (the send gives
    // up after a short grace).
    (void)Send(rank, wire::Encode(0, wire::Shutdown{1, wire::kShutdownRankDied}), f->figures);
  }
  s.failure = why;
  SlaveFigures& figures = f->figures->slaves[static_cast<size_t>(rank - 1)];
  figures.dropped = true;
  figures.failure = why;
  figures.host = s.host;
  if (!f->done[static_cast<size_t>(rank)]) {
    f->done[static_cast<size_t>(rank)] = true;
    --f->remaining;
  }
  {
    // The preview: its tiles are no longer its own (the others take them), and it is gone.
    std::lock_guard lock(assigned_mu_);
    assigned_[static_cast<size_t>(rank - 1)].clear();
    dropped_[static_cast<size_t>(rank - 1)] = (lost ? "lost: " : "failed: ") + why;
  }
  std::vector<render::SampleResult> merged;
  const std::vector<render::Tile> back = f->ledger.Release(rank, &merged);
  f->film->Unmerge(merged);
  f->returned.insert(f->returned.end(), back.begin(), back.end());
  // The host: on a cluster the operator looks for the bad disk or node there.
  const std::string on = s.host.empty() ? std::string() : " (on " + s.host + ")";
  const std::string tiles =
      back.empty() ? std::string("it had no tile in flight")
                   : StrFormat("its %zu unfinished tiles (%zu samples taken back) go to the other "
                               "slaves", back.size(), merged.size());
  LOG_WARNING("master", "rank %d%s %s: %s; %s", rank, on.c_str(), lost ? "is lost" : "failed",
              why.c_str(), tiles.c_str());
  // The others read its blocks from disk from now on (--blocks rem).
  for (int r = 1; r < net_->size(); ++r)
    if (!slaves_[static_cast<size_t>(r)].dropped)
      (void)Send(r, wire::Encode(0, wire::RankLost{static_cast<uint32_t>(rank), lost ? 1u : 0u}),
                 f->figures);
  if (f->remaining == 0 && WorkLeft(*f)) {
    // One cause for all (a store path none can open, say) is said once, not once a rank.
    bool same = true;
    for (int r = 2; r < net_->size(); ++r)
      same = same && slaves_[static_cast<size_t>(r)].failure == slaves_[1].failure;
    if (same && net_->size() > 2)
      return Status::Error(StrFormat("no slave is left to finish the frame: ranks 1 to %d: %s",
                                     net_->size() - 1, slaves_[1].failure.c_str()));
    std::string all;
    for (int r = 1; r < net_->size(); ++r)
      all += StrFormat("%srank %d: %s", all.empty() ? "" : "; ", r,
                       slaves_[static_cast<size_t>(r)].failure.c_str());
    return Status::Error("no slave is left to finish the frame: " + all);
  }
  return AnswerHeldRequests(f);
}

Status MasterNode::CheckHeartbeats(Frame* f) {
  const auto now = Clock::now();
  // The master reads messages on this thread between checks; if it was away (writing the
  // image between frames, a checkpoint, a convergence row), the heartbeats are still queued:
  // that time counts as heard, and the queue is read before anyone is judged.
  const auto away = now - last_check_;
  last_check_ = now;
  if (away > options_.lost_after / 2) {
    for (SlaveState& s : slaves_) s.last_heard += away;
    return OkStatus();
  }
  for (int r = 1; r < net_->size(); ++r) {
    SlaveState& s = slaves_[static_cast<size_t>(r)];
    const auto allowed = s.heard ? options_.lost_after : options_.lost_after + options_.first_word_grace;
    if (s.dropped || now - s.last_heard < allowed) continue;
    const double silent = std::chrono::duration<double>(now - s.last_heard).count();
    RAYSTACK_RETURN_IF_ERROR(Drop(f, r, true, StrFormat("no word from it for %.1f s", silent)));
  }
  return OkStatus();
}

Status MasterNode::CheckHello(int rank, const wire::Hello& hello) {
  const std::string host = wire::HelloText(hello.host);
  slaves_[static_cast<size_t>(rank)].host = host;  // named in its figures and warnings
  if (!options_.identity) return OkStatus();
  JobIdentity& job = *options_.identity;
  const std::string who = StrFormat("rank %d (on %s)", rank, host.empty() ? "an unnamed host" : host.c_str());
  const std::string build = wire::HelloText(hello.build);
  // The field holds 39 bytes: a longer id is compared as far as it goes.
  if (build != job.build.substr(0, sizeof hello.build - 1))
    return Status::Error(StrFormat("%s runs raystack %s, the master %s: run the same build on "
                                   "every rank", who.c_str(), build.c_str(), job.build.c_str()));
  if (!job.store) {
    job.store = hello.store_checksum;  // the master cannot read the store: the first slave's
    store_from_ = rank;
  }
  if (hello.store_checksum != *job.store && store_from_ == 0)
    return Status::Error(StrFormat(
        "%s reads another store than the master: its index checksum is %016llx, not %016llx (a "
        "copy of another model, or of an older conversion); every rank must read a copy of the "
        "same store", who.c_str(), static_cast<unsigned long long>(hello.store_checksum),
        static_cast<unsigned long long>(*job.store)));
  if (hello.store_checksum != *job.store)  // which one is right, the master cannot tell
    return Status::Error(StrFormat(
        "%s and rank %d read different stores (index checksums %016llx and %016llx; the master "
        "cannot read the store to tell which is right); every rank must read a copy of the same "
        "store", who.c_str(), store_from_, static_cast<unsigned long long>(hello.store_checksum),
        static_cast<unsigned long long>(*job.store)));
  if (hello.scene_checksum != job.scene)
    return Status::Error(StrFormat("%s read another scene than the master: its cameras, lights, "
                                   "materials, background or integrator differ; every rank must "
                                   "read the same scene file", who.c_str()));
  const bool remote = (hello.flags & wire::kHelloRemoteBlocks) != 0;
  if (!job.remote_blocks) job.remote_blocks = remote;
  if (remote != *job.remote_blocks)
    return Status::Error(StrFormat(
        "%s reads blocks %s, the rest of the job %s: --blocks auto decides on each rank from its own "
        "--cache-mb; give every rank the same --cache-mb, or --blocks loc or rem", who.c_str(),
        remote ? "from peers (rem)" : "from disk (loc)", remote ? "from disk (loc)" : "from peers (rem)"));
  return OkStatus();
}

Status MasterNode::Handle(Frame* f, transport::Envelope e) {
  const int slaves = net_->size() - 1;
  if (e.from < 1 || e.from > slaves)
    return Status::Error(StrFormat("message from rank %d, which is not a slave", e.from));
  SlaveState& state = slaves_[static_cast<size_t>(e.from)];
  if (state.dropped) return OkStatus();  // whatever a dropped slave still sends is ignored
  state.last_heard = Clock::now();
  state.heard = true;
  SlaveFigures& from = f->figures->slaves[static_cast<size_t>(e.from - 1)];
  from.bytes_received += e.bytes.size();
  const Expected<wire::Message> m = wire::Decode(e.bytes, e.from);
  if (!m.ok()) {
    // Another protocol: it cannot read the shutdown either (a malformed message of this
    // protocol ends the job too, but its sender can be told so).
    if (!wire::SpeaksThisProtocol(e.bytes)) state.deaf = true;
    return m.status();
  }
  switch (m->type()) {
    case wire::MessageType::kTileRequest: {
      const wire::TileRequest r = m->tile_request();
      if (r.frame > f->number) {
        f->later.push_back(std::move(e));
        return OkStatus();
      }
      if (r.frame < f->number)
        return Status::Error(StrFormat("rank %d asks for a tile of frame %u, which is over",
                                       e.from, r.frame));
      return Answer(f, e.from, r.thread);
    }
    case wire::MessageType::kPixelBatch: {
      if (m->batch_header().frame != f->number)
        return Status::Error(StrFormat("rank %d sent pixels of frame %u during frame %u",
                                       e.from, m->batch_header().frame, f->number));
      m->batch_samples(&f->samples);
      for (const render::SampleResult& s : f->samples)
        if (s.pixel >= static_cast<uint64_t>(f->film->width()) * static_cast<uint64_t>(f->film->height()))
          return Status::Error(StrFormat("rank %d sent a sample of pixel %u, outside the %dx%d "
                                         "image", e.from, s.pixel, f->film->width(),
                                         f->film->height()));
      RAYSTACK_RETURN_IF_ERROR(f->ledger.Record(e.from, f->samples));
      f->film->Merge(f->samples, m->batch_header().rays);
      from.pixel_bytes += e.bytes.size();
      if (f->ledger.unfinished() == 0) return AnswerHeldRequests(f);
      return OkStatus();
    }
    case wire::MessageType::kFrameDone: {
      const wire::FrameDone d = m->frame_done();
      if (d.frame != f->number || f->done[static_cast<size_t>(e.from)])
        return Status::Error(StrFormat("rank %d reports frame %u done during frame %u",
                                       e.from, d.frame, f->number));
      // Its times go into the figures and the --stats JSON: a NaN or an infinity ("nan" in the
      // JSON) would make the file unreadable.
      for (const auto& [name, value] : {std::pair<const char*, double>{"seconds", d.seconds},
                                        {"busy_seconds", d.busy_seconds},
                                        {"fetch_wait_seconds", d.fetch_wait_seconds},
                                        {"ray_cpu_seconds", d.ray_cpu_seconds},
                                        {"loader_cpu_seconds", d.loader_cpu_seconds},
                                        {"process_cpu_seconds", d.process_cpu_seconds},
                                        {"tile_wait_seconds", d.tile_wait_seconds},
                                        {"block_wait_seconds", d.block_wait_seconds},
                                        {"engine_seconds", d.engine_seconds},
                                        {"loader_busy_seconds", d.loader_busy_seconds}})
        // (Bounded too: two slaves' 1e308 added up to an infinite imbalance.)
        if (!(value >= 0) || !(value <= 1e9))
          return Status::Error(StrFormat("rank %d reports frame %u done with %s %g", e.from,
                                         d.frame, name, value));
      if (!(d.cache_hit_rate >= 0 && d.cache_hit_rate <= 1))
        return Status::Error(StrFormat("rank %d reports frame %u done with cache_hit_rate %g",
                                       e.from, d.frame, d.cache_hit_rate));
      f->done[static_cast<size_t>(e.from)] = true;
      from.done = d;
      from.host = slaves_[static_cast<size_t>(e.from)].host;  // its hello may come after the start
      --f->remaining;
      return OkStatus();
    }
    case wire::MessageType::kError:
      // The frame goes on with the others; the slave waits for the end of the job.
      return Drop(f, e.from, false, m->error_text());
    case wire::MessageType::kHello:
      return CheckHello(e.from, m->hello());
    case wire::MessageType::kHeartbeat:
      return OkStatus();
    case wire::MessageType::kTileAssign:
    case wire::MessageType::kShutdown:
    case wire::MessageType::kRankLost:
      return Status::Error(StrFormat("rank %d sent a %s, which only the master sends", e.from,
                                     wire::MessageTypeName(m->type())));
    case wire::MessageType::kBlockRequest:
    case wire::MessageType::kBlockData:
      return Status::Error(StrFormat("rank %d sent the master a %s, which slaves exchange "
                                     "among themselves", e.from, wire::MessageTypeName(m->type())));
  }
  return OkStatus();
}

Status MasterNode::RunFrame(uint32_t frame, std::vector<render::Tile> tiles, uint32_t spp,
                            render::Film* film, const std::function<void()>& on_progress,
                            FrameFigures* figures) {
  render::FramePlan plan;
  plan.width = film->width();
  plan.height = film->height();
  plan.passes.push_back({0, spp});
  plan.AddSweep(std::move(tiles), 0, true);
  return RunFrame(frame, plan, film, [&] { on_progress(); return true; }, figures);
}

Status MasterNode::RunFrame(uint32_t frame, const render::FramePlan& plan, render::Film* film,
                            const std::function<bool()>& keep_going, FrameFigures* figures) {
  const auto start = Clock::now();
  const int slaves = net_->size() - 1;
  CHECK(slaves >= 1);
  figures->slaves.assign(static_cast<size_t>(slaves), SlaveFigures{});
  Frame f{frame, film, figures, &plan, 0, nullptr, {}, false, TileLedger(film->width(), plan.spp()),
          std::vector<bool>(static_cast<size_t>(net_->size()), false), 0, {}, {}, {}};
  if (!plan.sweeps.empty()) f.scheduler = std::make_unique<TileScheduler>(plan.Tiles(0), slaves);
  {
    std::lock_guard lock(assigned_mu_);
    assigned_.assign(static_cast<size_t>(slaves), {});
    dropped_.resize(static_cast<size_t>(slaves));
  }
  for (int r = 1; r <= slaves; ++r) {
    SlaveFigures& s = figures->slaves[static_cast<size_t>(r - 1)];
    s.rank = r;
    const SlaveState& state = slaves_[static_cast<size_t>(r)];
    s.host = state.host;
    if (state.dropped) {  // dropped in an earlier frame
      s.dropped = true;
      s.failure = state.failure;
      f.done[static_cast<size_t>(r)] = true;
    } else {
      ++f.remaining;
    }
  }
  if (f.remaining == 0) return Status::Error("no slave is left to render the frame");
  // A stop rule may hold from the start; once one holds, requests held back get their answer.
  auto check_stop = [&]() -> Status {
    if (f.stopped || keep_going()) return OkStatus();
    f.stopped = true;
    return AnswerHeldRequests(&f);
  };
  RAYSTACK_RETURN_IF_ERROR(check_stop());
  auto last_progress = Clock::now();

  while (f.remaining > 0) {
    std::optional<transport::Envelope> e;
    if (!early_.empty()) {
      e = std::move(early_.front());
      early_.pop_front();
    } else {
      Expected<std::optional<transport::Envelope>> got =
          net_->Receive(std::chrono::milliseconds(25));
      if (!got.ok()) return got.status();
      e = std::move(*got);
    }
    if (e) RAYSTACK_RETURN_IF_ERROR(Handle(&f, std::move(*e)));
    if (!e || Clock::now() - last_progress > std::chrono::milliseconds(25)) {
      RAYSTACK_RETURN_IF_ERROR(CheckHeartbeats(&f));
      RAYSTACK_RETURN_IF_ERROR(check_stop());
      last_progress = Clock::now();
    }
  }
  if (WorkLeft(f)) return Status::Error(StrFormat("frame %u: tiles were left unfinished", frame));
  for (auto& later : f.later) early_.push_back(std::move(later));
  keep_going();
  figures->seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return OkStatus();
}

}  // namespace raystack::master
