#include "slave/peer_blocks.h"

#include <chrono>

#include "common/base/log.h"
#include "common/base/thread_name.h"

namespace raystack::slave {

PeerBlocks::PeerBlocks(transport::Transport* net, const store::StoreReader& store,
                       FaultOptions faults)
    : net_(net), store_(store), disk_(store, faults), slaves_(net->size() - 1),
      lost_(static_cast<size_t>(net->size()), false) {
  const uint32_t count = static_cast<uint32_t>(store.blocks().size());
  const int me = net->rank();
  while (own_first_ < count && BlockOwner(own_first_, count, slaves_) < me) ++own_first_;
  own_end_ = own_first_;
  while (own_end_ < count && BlockOwner(own_end_, count, slaves_) == me) ++own_end_;
  owned_ = std::vector<OwnedBlock>(own_end_ - own_first_);
  for (uint32_t b = own_first_; b < own_end_; ++b) owned_bytes_ += store.blocks()[b].stored_bytes;
  server_ = std::thread([this] {
    SetThreadName("rs-serve");
    ServeLoop();
  });
}

PeerBlocks::~PeerBlocks() {
  Stop();
  server_.join();
}

void PeerBlocks::Stop() {
  std::lock_guard lock(mu_);
  stopped_ = true;
  for (auto& [id, p] : pending_) p->cv.notify_all();
  serve_cv_.notify_all();
}

void PeerBlocks::OwnerLost(int rank) {
  std::lock_guard lock(mu_);
  if (rank < 0 || rank >= static_cast<int>(lost_.size())) return;
  lost_[static_cast<size_t>(rank)] = true;
  for (auto& [id, p] : pending_)
    if (p->owner == rank && !p->done) {
      p->owner_lost = p->done = true;
      p->cv.notify_all();
    }
}

Status PeerBlocks::Own(uint32_t block, std::vector<uint8_t>* append) {
  OwnedBlock& o = owned_[block - own_first_];
  std::call_once(o.loaded, [&] {
    const uint32_t ids[1] = {block};
    o.status = disk_.ReadRun(ids, &o.bytes);
    o.ready.store(true, std::memory_order_release);
  });
  if (!o.status.ok()) return o.status;
  append->insert(append->end(), o.bytes.begin(), o.bytes.end());
  return OkStatus();
}

Status PeerBlocks::Fetch(int owner, uint32_t first, uint32_t count, std::vector<uint8_t>* append) {
  uint32_t id;
  // Once its owner is lost, a block comes from disk, as with --blocks loc.
  auto from_disk = [&]() -> Status {
    std::vector<uint32_t> ids(count);
    for (uint32_t k = 0; k < count; ++k) ids[k] = first + k;
    std::vector<uint8_t> bytes;
    RAYSTACK_RETURN_IF_ERROR(disk_.ReadRun(ids, &bytes));
    append->insert(append->end(), bytes.begin(), bytes.end());
    return OkStatus();
  };
  {
    // One critical section: an OwnerLost between a check and the request would leave the
    // request waiting for an answer that never comes.
    std::unique_lock lock(mu_);
    if (stopped_) return Status::Error("the job is ending");
    if (lost_[static_cast<size_t>(owner)]) {
      lock.unlock();
      return from_disk();
    }
    id = next_request_++;
    auto p = std::make_unique<Pending>();
    p->owner = owner;
    p->first = first;
    p->count = count;
    pending_.emplace(id, std::move(p));
  }
  fetches_.fetch_add(1, std::memory_order_relaxed);
  const auto asked = std::chrono::steady_clock::now();
  const Status sent = net_->Send(owner, wire::Encode(static_cast<uint32_t>(net_->rank()),
                                                     wire::BlockRequest{id, first, count, 0}));
  std::unique_lock lock(mu_);
  Pending& waiting = *pending_.at(id);
  // A peer that never answers must not hang the job: a minute is far beyond any real fetch.
  const bool answered = sent.ok() && waiting.cv.wait_for(lock, std::chrono::minutes(1), [&] {
    return waiting.done || stopped_;
  });
  std::unique_ptr<Pending> taken = std::move(pending_.at(id));
  pending_.erase(id);
  lock.unlock();
  Pending& p = *taken;
  const auto waited = std::chrono::steady_clock::now() - asked;
  fetch_wait_ns_.fetch_add(
      static_cast<uint64_t>(std::chrono::duration_cast<std::chrono::nanoseconds>(waited).count()),
      std::memory_order_relaxed);
  if (p.owner_lost) return from_disk();
  RAYSTACK_RETURN_IF_ERROR(sent);
  if (!answered || !p.done)
    return Status::Error(StrFormat("blocks %u-%u: rank %d did not answer", first,
                                   first + count - 1, owner));
  if (!p.status.ok()) return p.status;
  from_peers_.fetch_add(p.bytes.size());
  append->insert(append->end(), p.bytes.begin(), p.bytes.end());
  return OkStatus();
}

Status PeerBlocks::ReadRun(std::span<const uint32_t> ids, std::vector<uint8_t>* bytes) {
  reads_.fetch_add(1);
  bytes->clear();
  const uint32_t count = static_cast<uint32_t>(store_.blocks().size());
  size_t i = 0;
  while (i < ids.size()) {
    const int owner = BlockOwner(ids[i], count, slaves_);
    size_t j = i + 1;
    while (j < ids.size() && BlockOwner(ids[j], count, slaves_) == owner) ++j;
    if (owner == net_->rank()) {
      for (size_t k = i; k < j; ++k) RAYSTACK_RETURN_IF_ERROR(Own(ids[k], bytes));
    } else {
      RAYSTACK_RETURN_IF_ERROR(Fetch(owner, ids[i], static_cast<uint32_t>(j - i), bytes));
    }
    i = j;
  }
  bytes_.fetch_add(bytes->size());
  return OkStatus();
}

Status PeerBlocks::OnRequest(int from, const wire::BlockRequest& r) {
  if (r.count == 0 || r.first < own_first_ || r.first >= own_end_ || r.count > own_end_ - r.first)
    return Status::Error(StrFormat("rank %d asked rank %d for blocks %u+%u, which it does not own",
                                   from, net_->rank(), r.first, r.count));
  bool in_memory = true;
  for (uint32_t b = r.first; b < r.first + r.count && in_memory; ++b)
    in_memory = owned_[b - own_first_].ready.load(std::memory_order_acquire);
  if (in_memory) {  // the common case once warm: answered without waking another thread
    Answer(from, r, &receive_scratch_);
    return OkStatus();
  }
  std::lock_guard lock(mu_);
  to_serve_.push_back({from, r});
  serve_cv_.notify_one();
  return OkStatus();
}

Status PeerBlocks::OnData(int from, const wire::Message& m) {
  const wire::BlockDataHeader d = m.block_data_header();
  std::lock_guard lock(mu_);
  auto it = pending_.find(d.request);
  if (it == pending_.end() || it->second->owner != from || it->second->first != d.first ||
      it->second->count != d.count)
    return Status::Error(StrFormat("rank %d sent blocks %u+%u this rank did not ask it for",
                                   from, d.first, d.count));
  Pending& p = *it->second;
  if (d.failed) {
    p.status = Status::Error(StrFormat("blocks %u-%u: their owner, rank %d, could not read them",
                                       d.first, d.first + d.count - 1, from));
  } else {
    uint64_t expected = 0;
    for (uint32_t b = d.first; b < d.first + d.count; ++b) expected += store_.blocks()[b].stored_bytes;
    const std::span<const uint8_t> bytes = m.block_data();
    if (bytes.size() != expected)
      p.status = Status::Error(StrFormat("blocks %u-%u from rank %d: %zu bytes, the index says %llu",
                                         d.first, d.first + d.count - 1, from, bytes.size(),
                                         static_cast<unsigned long long>(expected)));
    else
      p.bytes.assign(bytes.begin(), bytes.end());
  }
  p.done = true;
  p.cv.notify_all();
  return OkStatus();
}

void PeerBlocks::Answer(int to, const wire::BlockRequest& r, std::vector<uint8_t>* bytes) {
  bytes->clear();
  Status st;
  for (uint32_t b = r.first; b < r.first + r.count && st.ok(); ++b) st = Own(b, bytes);
  if (!st.ok()) LOG_ERROR("slave", "serving rank %d: %s", to, st.message().c_str());
  const wire::BlockDataHeader h{r.request, r.first, r.count, st.ok() ? 0u : 1u};
  // Posted, never a blocking send: this may run on the receiving thread, and a receiver
  // waiting for a peer that is itself waiting to answer this one would never return.
  const std::span<const uint8_t> stored =
      st.ok() ? std::span<const uint8_t>(*bytes) : std::span<const uint8_t>();
  const Status sent =
      net_->Post(to, wire::EncodeBlockData(static_cast<uint32_t>(net_->rank()), h, stored));
  if (!sent.ok()) LOG_ERROR("slave", "%s", sent.message().c_str());
  if (st.ok()) to_peers_.fetch_add(bytes->size());
}

void PeerBlocks::ServeLoop() {
  std::vector<uint8_t> bytes;
  for (;;) {
    Served s;
    {
      std::unique_lock lock(mu_);
      serve_cv_.wait(lock, [&] { return stopped_ || !to_serve_.empty(); });
      if (to_serve_.empty()) return;
      s = to_serve_.front();
      to_serve_.pop_front();
    }
    Answer(s.to, s.request, &bytes);
  }
}

}  // namespace raystack::slave
