#include "slave/ray_queues.h"

#include <algorithm>

#include "common/base/check.h"

namespace raystack::slave {

uint32_t RayQueues::Create(uint32_t block, State state) {
  CHECK(queue_of_[block] == kNone);
  uint32_t q;
  if (free_queues_.empty()) {
    q = static_cast<uint32_t>(queues_.size());
    queues_.emplace_back();
  } else {
    q = free_queues_.back();
    free_queues_.pop_back();
  }
  Queue& queue = queues_[q];
  queue.block = block;
  queue.state = state;
  queue.priority = 0;
  queue.chunks.clear();
  queue.last_count = kChunkRays;
  queue.rays = 0;
  queue_of_[block] = q;
  if (state == State::kReady) ready_.push({0, ++sequence_, q});
  return q;
}

uint32_t RayQueues::NewChunk() {
  ++chunks_in_use_;
  peak_chunks_ = std::max(peak_chunks_, chunks_in_use_);
  if (!free_chunks_.empty()) {
    const uint32_t c = free_chunks_.back();
    free_chunks_.pop_back();
    return c;
  }
  chunks_.push_back(std::make_unique<RayChunk>());
  return static_cast<uint32_t>(chunks_.size() - 1);
}

void RayQueues::Push(uint32_t q, const RayRecord& ray) {
  Queue& queue = queues_[q];
  if (queue.last_count == kChunkRays) {
    queue.chunks.push_back(NewChunk());
    queue.last_count = 0;
  }
  chunks_[queue.chunks.back()]->rays[queue.last_count++] = ray;
  ++queue.rays;
  ++rays_;
  peak_rays_ = std::max(peak_rays_, rays_);
  if (ray.priority > queue.priority) {
    queue.priority = ray.priority;
    // A ready queue whose priority rose is pushed again; the stale entry is skipped later.
    if (queue.state == State::kReady) ready_.push({queue.priority, ++sequence_, q});
  }
}

void RayQueues::MarkReady(uint32_t q) {
  Queue& queue = queues_[q];
  if (queue.state == State::kReady) return;
  queue.state = State::kReady;
  ready_.push({queue.priority, ++sequence_, q});
}

uint32_t RayQueues::PopReady() {
  while (!ready_.empty()) {
    const ReadyItem item = ready_.top();
    ready_.pop();
    const Queue& queue = queues_[item.queue];
    if (queue.state != State::kReady || queue.rays == 0 || queue_of_[queue.block] != item.queue)
      continue;  // stale: traced already, or closed
    return item.queue;
  }
  return kNone;
}

void RayQueues::TakeChunks(uint32_t q, std::vector<uint32_t>* chunks, uint32_t* last_count) {
  Queue& queue = queues_[q];
  chunks->swap(queue.chunks);
  queue.chunks.clear();
  *last_count = queue.last_count;
  rays_ -= queue.rays;
  queue.rays = 0;
  queue.priority = 0;
  queue.last_count = kChunkRays;
}

void RayQueues::Recycle(const std::vector<uint32_t>& chunks) {
  for (uint32_t c : chunks) free_chunks_.push_back(c);
  chunks_in_use_ -= chunks.size();
}

void RayQueues::Close(uint32_t q) {
  Queue& queue = queues_[q];
  CHECK(queue.rays == 0);
  queue_of_[queue.block] = kNone;
  free_queues_.push_back(q);
}

void RayQueues::Reset() {
  std::fill(queue_of_.begin(), queue_of_.end(), kNone);
  free_queues_.clear();
  for (uint32_t q = static_cast<uint32_t>(queues_.size()); q-- > 0;) {
    queues_[q].chunks.clear();
    free_queues_.push_back(q);
  }
  free_chunks_.clear();
  for (uint32_t c = static_cast<uint32_t>(chunks_.size()); c-- > 0;) free_chunks_.push_back(c);
  ready_ = {};
  sequence_ = 0;
  rays_ = peak_rays_ = 0;
  chunks_in_use_ = peak_chunks_ = 0;
}

}  // namespace raystack::slave
