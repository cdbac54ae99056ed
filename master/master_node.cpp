#include "master/master_node.h"

#include <algorithm>
#include <chrono>

#include "common/base/check.h"
#include "common/base/log.h"
#include "master/tile_scheduler.h"

namespace raystack::master {

double FrameFigures::imbalance() const {
  double sum = 0, max = 0;
  for (const SlaveFigures& s : slaves) {
    sum += s.done.seconds;
    max = std::max(max, s.done.seconds);
  }
  return max > 0 ? 1.0 - sum / static_cast<double>(slaves.size()) / max : 0.0;
}

Status MasterNode::Send(int to, const std::vector<uint8_t>& bytes, FrameFigures* figures) {
  figures->slaves[static_cast<size_t>(to - 1)].bytes_sent += bytes.size();
  return net_->Send(to, bytes);
}

bool MasterNode::Shutdown(uint32_t reason, std::chrono::milliseconds timeout) {
  std::vector<bool> acknowledged(static_cast<size_t>(net_->size()), false);
  int waiting = 0;
  for (int r = 1; r < net_->size(); ++r) {
    const Status s = net_->Send(r, wire::Encode(0, wire::Shutdown{reason, 0}));
    if (s.ok()) {
      ++waiting;
    } else {
      LOG_WARNING("master", "%s", s.message().c_str());
    }
  }
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (waiting > 0 && std::chrono::steady_clock::now() < deadline) {
    Expected<std::optional<transport::Envelope>> got = net_->Receive(std::chrono::milliseconds(100));
    if (!got.ok()) break;
    if (!got->has_value()) continue;
    const Expected<wire::Message> m = wire::Decode((*got)->bytes, (*got)->from);
    const int from = (*got)->from;
    if (m.ok() && m->type() == wire::MessageType::kShutdown && from > 0 &&
        from < net_->size() && !acknowledged[static_cast<size_t>(from)]) {
      acknowledged[static_cast<size_t>(from)] = true;
      --waiting;
    }
  }
  early_.clear();
  return waiting == 0;
}

std::vector<std::vector<render::Tile>> MasterNode::TilesAssigned() const {
  std::lock_guard lock(assigned_mu_);
  return assigned_;
}

Status MasterNode::RunFrame(uint32_t frame, std::vector<render::Tile> tiles, render::Film* film,
                            const std::function<void()>& on_progress, FrameFigures* figures) {
  const auto start = std::chrono::steady_clock::now();
  const int slaves = net_->size() - 1;
  CHECK(slaves >= 1);
  figures->slaves.assign(static_cast<size_t>(slaves), SlaveFigures{});
  for (int i = 0; i < slaves; ++i) figures->slaves[static_cast<size_t>(i)].rank = i + 1;
  TileScheduler scheduler(std::move(tiles), slaves);
  {
    std::lock_guard lock(assigned_mu_);
    assigned_.assign(static_cast<size_t>(slaves), {});
  }
  std::vector<bool> done(static_cast<size_t>(slaves), false);
  int remaining = slaves;
  std::vector<render::SampleResult> samples;
  std::deque<transport::Envelope> later;  // for frames after this one
  auto last_progress = std::chrono::steady_clock::now();

  while (remaining > 0) {
    transport::Envelope e;
    if (!early_.empty()) {
      e = std::move(early_.front());
      early_.pop_front();
    } else {
      Expected<std::optional<transport::Envelope>> got =
          net_->Receive(std::chrono::milliseconds(100));
      if (!got.ok()) return got.status();
      if (!got->has_value()) {
        on_progress();
        continue;
      }
      e = std::move(**got);
    }
    if (e.from < 1 || e.from > slaves)
      return Status::Error(StrFormat("message from rank %d, which is not a slave", e.from));
    SlaveFigures& from = figures->slaves[static_cast<size_t>(e.from - 1)];
    from.bytes_received += e.bytes.size();
    const Expected<wire::Message> m = wire::Decode(e.bytes, e.from);
    if (!m.ok()) return m.status();
    switch (m->type()) {
      case wire::MessageType::kTileRequest: {
        const wire::TileRequest r = m->tile_request();
        if (r.frame > frame) {
          later.push_back(std::move(e));
          continue;
        }
        if (r.frame < frame)
          return Status::Error(StrFormat("rank %d asks for a tile of frame %u, which is over",
                                         e.from, r.frame));
        wire::TileAssign a{};
        a.frame = frame;
        a.thread = r.thread;
        render::Tile t;
        if (scheduler.Next(e.from - 1, &t)) {
          a.x0 = t.x0, a.y0 = t.y0, a.x1 = t.x1, a.y1 = t.y1;
          std::lock_guard lock(assigned_mu_);
          assigned_[static_cast<size_t>(e.from - 1)].push_back(t);
        } else {
          a.none = 1;
        }
        RAYSTACK_RETURN_IF_ERROR(Send(e.from, wire::Encode(0, a), figures));
        break;
      }
      case wire::MessageType::kPixelBatch: {
        if (m->batch_header().frame != frame)
          return Status::Error(StrFormat("rank %d sent pixels of frame %u during frame %u",
                                         e.from, m->batch_header().frame, frame));
        m->batch_samples(&samples);
        for (const render::SampleResult& s : samples)
          if (s.pixel >= static_cast<uint64_t>(film->width()) * static_cast<uint64_t>(film->height()))
            return Status::Error(StrFormat("rank %d sent a sample of pixel %u, outside the %dx%d "
                                           "image", e.from, s.pixel, film->width(), film->height()));
        film->Merge(samples);
        from.pixel_bytes += e.bytes.size();
        break;
      }
      case wire::MessageType::kFrameDone: {
        const wire::FrameDone d = m->frame_done();
        if (d.frame != frame || done[static_cast<size_t>(e.from - 1)])
          return Status::Error(StrFormat("rank %d reports frame %u done during frame %u",
                                         e.from, d.frame, frame));
        done[static_cast<size_t>(e.from - 1)] = true;
        from.done = d;
        --remaining;
        break;
      }
      case wire::MessageType::kError:
        return Status::Error(StrFormat("rank %d: %s", e.from, m->error_text().c_str()));
      case wire::MessageType::kHello:
        break;
      case wire::MessageType::kTileAssign:
      case wire::MessageType::kShutdown:
        return Status::Error(StrFormat("rank %d sent a %s, which only the master sends", e.from,
                                       wire::MessageTypeName(m->type())));
      case wire::MessageType::kBlockRequest:
      case wire::MessageType::kBlockData:
        return Status::Error(StrFormat("rank %d sent the master a %s, which slaves exchange "
                                       "among themselves", e.from, wire::MessageTypeName(m->type())));
    }
    if (std::chrono::steady_clock::now() - last_progress > std::chrono::milliseconds(100)) {
      on_progress();
      last_progress = std::chrono::steady_clock::now();
    }
  }
  for (auto& e : later) early_.push_back(std::move(e));
  on_progress();
  figures->seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return OkStatus();
}

}  // namespace raystack::master
