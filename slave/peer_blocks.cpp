#include "slave/peer_blocks.h"

#include <chrono>
#include <utility>

#include "common/base/log.h"
#include "common/base/thread_name.h"

namespace raystack::slave {

PeerBlocks::PeerBlocks(transport::Transport* net, const store::StoreReader& store,
                       FaultOptions faults)
    : net_(net), store_(store), disk_(store, faults), slaves_(net->size() - 1),
      owners_(static_cast<size_t>(net->size())),
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
  for (auto& [id, b] : sent_) b->cv.notify_all();
  for (OwnerQueue& q : owners_)
    if (q.open) q.open->cv.notify_all();
  serve_cv_.notify_all();
}

void PeerBlocks::OwnerLost(int rank) {
  std::lock_guard lock(mu_);
  if (rank < 0 || rank >= static_cast<int>(lost_.size())) return;
  lost_[static_cast<size_t>(rank)] = true;
  auto lose = [](Batch* b) {
    b->from_disk = b->done = true;
    b->cv.notify_all();
  };
  for (auto it = sent_.begin(); it != sent_.end();) {
    if (it->second->owner == rank) {
      lose(it->second.get());
      it = sent_.erase(it);
    } else {
      ++it;
    }
  }
  OwnerQueue& q = owners_[static_cast<size_t>(rank)];
  if (q.open) {
    runs_waiting_ -= q.open->runs.size();
    lose(q.open.get());
  }
  q.open = nullptr;
  q.in_flight = 0;
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

void PeerBlocks::Answered(OwnerQueue* q) {
  --q->in_flight;
  if (q->open) q->open->cv.notify_all();  // its leader may send it now
}

uint64_t PeerBlocks::RunBytes(uint32_t first, uint32_t count) const {
  uint64_t bytes = 0;
  for (uint32_t b = first; b < first + count; ++b) bytes += store_.blocks()[b].stored_bytes;
  return bytes;
}

void PeerBlocks::SendBatch(const std::shared_ptr<Batch>& b, std::unique_lock<std::mutex>* lock) {
  OwnerQueue& q = owners_[static_cast<size_t>(b->owner)];
  if (q.open == b) q.open = nullptr;
  runs_waiting_ -= b->runs.size();
  b->sent = true;
  b->request = next_request_++;
  sent_.emplace(b->request, b);
  ++q.in_flight;
  // The runs are final once the batch leaves the open slot: no fetch joins it any more.
  const std::vector<uint8_t> message =
      wire::EncodeBlockRequest(static_cast<uint32_t>(net_->rank()), b->request, b->runs);
  lock->unlock();
  fetches_.fetch_add(1, std::memory_order_relaxed);
  runs_fetched_.fetch_add(b->runs.size(), std::memory_order_relaxed);
  const auto asked = std::chrono::steady_clock::now();
  const Status sent = net_->Send(b->owner, message);
  lock->lock();
  if (!sent.ok() && !b->done) {
    b->status = sent;
    b->done = true;
    sent_.erase(b->request);
    Answered(&q);
  }
  // The leader measures its request's round trip; the members wait for the same answer.
  b->cv.wait_for(*lock, std::chrono::minutes(1), [&] { return b->done || stopped_; });
  fetch_wait_ns_.fetch_add(static_cast<uint64_t>(
                               std::chrono::duration_cast<std::chrono::nanoseconds>(
                                   std::chrono::steady_clock::now() - asked)
                                   .count()),
                           std::memory_order_relaxed);
}

Status PeerBlocks::Fetch(int owner, uint32_t first, uint32_t count, std::vector<uint8_t>* append) {
  // Once its owner is lost, a block comes from disk, as with --blocks loc.
  auto from_disk = [&]() -> Status {
    std::vector<uint32_t> ids(count);
    for (uint32_t k = 0; k < count; ++k) ids[k] = first + k;
    std::vector<uint8_t> bytes;
    RAYSTACK_RETURN_IF_ERROR(disk_.ReadRun(ids, &bytes));
    append->insert(append->end(), bytes.begin(), bytes.end());
    return OkStatus();
  };
  const uint64_t run_bytes = RunBytes(first, count);
  // A run no answer may carry (a block over kMaxAnswerBytes: a store made with a large
  // --max-block-kb; the loader's runs of several blocks are far smaller) is read as with loc.
  if (run_bytes > kMaxAnswerBytes) return from_disk();
  std::shared_ptr<Batch> b;
  uint64_t offset = 0;  // this run's bytes in the answer
  bool stopped = false;
  {
    // One critical section from the lost check to joining a batch: an OwnerLost in between
    // would leave the batch waiting for an answer that never comes.
    std::unique_lock lock(mu_);
    if (stopped_) return Status::Error("the job is ending");
    if (lost_[static_cast<size_t>(owner)]) {
      lock.unlock();
      return from_disk();
    }
    transport::AnswerWait waiting(net_);  // the receiving thread looks for the answer at once
    OwnerQueue& q = owners_[static_cast<size_t>(owner)];
    if (q.open && (q.open->runs.size() >= kMaxBatchRuns ||
                   q.open->expected_bytes + run_bytes > kMaxBatchBytes)) {
      q.open->full = true;  // its leader sends it now; this run starts the next one
      q.open->cv.notify_all();
      q.open = nullptr;
    }
    bool leader = false;
    if (!q.open) {
      q.open = std::make_shared<Batch>();
      q.open->owner = owner;
      leader = true;
    }
    b = q.open;
    offset = b->expected_bytes;
    b->runs.push_back({first, count});
    ++runs_waiting_;
    b->expected_bytes += run_bytes;
    ++b->members;
    if (leader) {
      // Sent once fewer than kMaxInFlightPerOwner requests are out (at once, usually); the
      // runs wanted meanwhile join it.
      const bool may_send = b->cv.wait_for(lock, std::chrono::minutes(1), [&] {
        return q.in_flight < kMaxInFlightPerOwner || b->full || b->done || stopped_;
      });
      if (may_send && !b->done && !stopped_) SendBatch(b, &lock);
    } else {
      b->cv.wait_for(lock, std::chrono::minutes(1), [&] { return b->done || stopped_; });
    }
    --b->members;
    if (!b->done && b->members == 0 && b->sent) {  // no answer in time, and nobody waits
      sent_.erase(b->request);
      Answered(&q);
    }
    if (!b->done && !b->sent && q.open == b) {  // stopped (or timed out) before it was sent
      q.open = nullptr;
      runs_waiting_ -= b->runs.size();
    }
    stopped = stopped_;
  }
  if (b->from_disk) return from_disk();
  if (!b->done)
    return stopped ? Status::Error("the job is ending")
                   : Status::Error(StrFormat("blocks %u-%u: rank %d did not answer", first,
                                             first + count - 1, owner));
  if (!b->status.ok()) return b->status;
  from_peers_.fetch_add(run_bytes);
  append->insert(append->end(), b->bytes.begin() + static_cast<ptrdiff_t>(offset),
                 b->bytes.begin() + static_cast<ptrdiff_t>(offset + run_bytes));
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

Status PeerBlocks::OnRequest(int from, const wire::Message& m) {
  const wire::BlockRequest r = m.block_request();
  m.block_runs(&receive_runs_);
  uint64_t bytes = 0;
  for (const wire::BlockRun& run : receive_runs_) {
    if (run.count == 0 || run.first < own_first_ || run.first >= own_end_ ||
        run.count > own_end_ - run.first)
      return Status::Error(StrFormat("rank %d asked rank %d for blocks %u+%u, which it does not own",
                                     from, net_->rank(), run.first, run.count));
    bytes += RunBytes(run.first, run.count);
  }
  if (bytes > kMaxAnswerBytes)
    return Status::Error(StrFormat("rank %d asked rank %d for %u runs of %llu bytes in one request "
                                   "(at most %llu)", from, net_->rank(), r.runs,
                                   static_cast<unsigned long long>(bytes),
                                   static_cast<unsigned long long>(kMaxAnswerBytes)));
  bool in_memory = true;
  for (const wire::BlockRun& run : receive_runs_)
    for (uint32_t b = run.first; b < run.first + run.count && in_memory; ++b)
      in_memory = owned_[b - own_first_].ready.load(std::memory_order_acquire);
  if (in_memory) {  // the common case once warm: answered without waking another thread
    Answer(from, r.request, receive_runs_, &receive_scratch_);
    return OkStatus();
  }
  std::lock_guard lock(mu_);
  to_serve_.push_back({from, r.request, receive_runs_});
  serve_cv_.notify_one();
  return OkStatus();
}

Status PeerBlocks::TakeServeFailure() {
  std::lock_guard lock(mu_);
  if (serve_failure_.ok()) return OkStatus();
  serve_failure_taken_ = true;
  return std::exchange(serve_failure_, OkStatus());
}

Status PeerBlocks::OnData(int from, const wire::Message& m, std::vector<uint8_t>* received) {
  const wire::BlockDataHeader d = m.block_data_header();
  std::lock_guard lock(mu_);
  auto it = sent_.find(d.request);
  if (it == sent_.end() && d.request < next_request_) {
    // A request this rank stopped waiting for: its owner was given up as lost (a stalled
    // rank answers its backlog when it runs again) or the wait timed out. Its fetches have
    // read the runs from disk or failed already; the answer is dropped.
    LOG_DEBUG("slave", "dropped rank %d's late answer to request %u", from, d.request);
    return OkStatus();
  }
  if (it == sent_.end() || it->second->owner != from || it->second->runs.size() != d.runs)
    return Status::Error(StrFormat("rank %d sent an answer (request %u, %u runs) this rank did "
                                   "not ask it for", from, d.request, d.runs));
  const std::shared_ptr<Batch> b = it->second;
  sent_.erase(it);
  Answered(&owners_[static_cast<size_t>(from)]);
  const wire::BlockRun& head = b->runs.front();
  if (d.failed) {
    // Its disk or its copy of the store failed; this rank's may not (with --blocks loc only
    // the slave whose read failed is dropped, so it is here too).
    LOG_WARNING("slave", "blocks %u-%u (and %zu more runs): their owner, rank %d, could not read "
                "them; reading them from disk", head.first, head.first + head.count - 1,
                b->runs.size() - 1, from);
    b->from_disk = true;
  } else {
    const std::span<const uint8_t> bytes = m.block_data();
    if (bytes.size() != b->expected_bytes)
      b->status = Status::Error(StrFormat("blocks %u-%u (and %zu more runs) from rank %d: %zu "
                                          "bytes, the index says %llu", head.first,
                                          head.first + head.count - 1, b->runs.size() - 1, from,
                                          bytes.size(),
                                          static_cast<unsigned long long>(b->expected_bytes)));
    else {
      // Moving a vector keeps its buffer, so `bytes` still points into it.
      b->message = std::move(*received);
      b->bytes = bytes;
    }
  }
  b->done = true;
  b->cv.notify_all();
  return OkStatus();
}

void PeerBlocks::Answer(int to, uint32_t request, std::span<const wire::BlockRun> runs,
                        std::vector<uint8_t>* bytes) {
  bytes->clear();
  Status st;
  for (const wire::BlockRun& run : runs)
    for (uint32_t b = run.first; b < run.first + run.count && st.ok(); ++b) st = Own(b, bytes);
  if (!st.ok()) {
    LOG_ERROR("slave", "serving rank %d: %s", to, st.message().c_str());
    std::lock_guard lock(mu_);
    if (serve_failure_.ok() && !serve_failure_taken_)
      serve_failure_ = Status::Error(StrFormat("%s (read for rank %d)", st.message().c_str(), to));
  }
  const wire::BlockDataHeader h{request, static_cast<uint32_t>(runs.size()), st.ok() ? 0u : 1u, 0};
  // Posted, never a blocking send: this may run on the receiving thread, and a receiver
  // waiting for a peer that is itself waiting to answer this one would never return.
  const std::span<const uint8_t> stored =
      st.ok() ? std::span<const uint8_t>(*bytes) : std::span<const uint8_t>();
  // Counted before the answer goes: once it is out, the asker may report before this returns.
  to_peers_.fetch_add(stored.size());
  const Status sent =
      net_->Post(to, wire::EncodeBlockData(static_cast<uint32_t>(net_->rank()), h, stored));
  if (!sent.ok()) {
    LOG_ERROR("slave", "%s", sent.message().c_str());
    to_peers_.fetch_sub(stored.size());
  }
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
    try {
      Answer(s.to, s.request, s.runs, &bytes);
    } catch (...) {  // out of memory: a failed answer, so the asker reads them itself at once
      try {
        (void)net_->Post(s.to, wire::EncodeBlockData(static_cast<uint32_t>(net_->rank()),
                                                     wire::BlockDataHeader{s.request, static_cast<uint32_t>(s.runs.size()), 1, 0}, {}));
      } catch (...) {  // not even that: the asker gives up waiting and reads them (a minute)
      }
    }
  }
}

}  // namespace raystack::slave
