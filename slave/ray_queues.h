#pragma once
// One ray thread's waiting queues, one per block that has rays waiting (thesis Fig. VI.3), and
// the choice of the next queue to trace. Rays are stored in 2 KB chunks of 32 records (the
// thesis's packets) from a pool that only grows to the peak: no allocation per ray. A queue is
// *ready* when its block is resident and pinned for this thread; ready queues are traced
// highest priority first (a queue's priority is the highest of its rays'), most recently
// readied first among equals.
// Owned by one thread; not thread-safe.

#include <cstdint>
#include <memory>
#include <queue>
#include <vector>

#include "slave/ray_record.h"

namespace raystack::slave {

inline constexpr uint32_t kChunkRays = 32;
struct RayChunk {
  RayRecord rays[kChunkRays];
};
static_assert(sizeof(RayChunk) == 2048);

class RayQueues {
 public:
  explicit RayQueues(uint32_t block_count) : queue_of_(block_count, kNone) {}

  enum class State : uint8_t { kWaiting, kReady };

  // The queue of `block`, or kNone.
  static constexpr uint32_t kNone = 0xffffffffu;
  uint32_t Find(uint32_t block) const { return queue_of_[block]; }
  // Creates the (empty) queue of `block` in `state`.
  uint32_t Create(uint32_t block, State state);
  void Push(uint32_t q, const RayRecord& ray);
  void MarkReady(uint32_t q);
  State state(uint32_t q) const { return queues_[q].state; }
  uint32_t block(uint32_t q) const { return queues_[q].block; }
  uint32_t size(uint32_t q) const { return queues_[q].rays; }

  // The ready queue to trace next, or kNone.
  uint32_t PopReady();
  // Moves the queue's chunks out (the caller traces them, then returns them with Recycle).
  // The queue stays, empty, so rays arriving meanwhile for the same block join it.
  void TakeChunks(uint32_t q, std::vector<uint32_t>* chunks, uint32_t* last_count);
  RayChunk& chunk(uint32_t c) { return *chunks_[c]; }
  void Recycle(const std::vector<uint32_t>& chunks);
  // Deletes an empty queue.
  void Close(uint32_t q);
  // Empties every queue and zeroes the peaks for a new frame; the chunks and queue records stay
  // allocated for reuse.
  void Reset();

  uint64_t rays() const { return rays_; }
  uint64_t peak_bytes() const { return peak_chunks_ * sizeof(RayChunk); }
  uint64_t peak_rays() const { return peak_rays_; }

 private:
  struct Queue {
    uint32_t block = 0;
    State state = State::kWaiting;
    uint16_t priority = 0;
    std::vector<uint32_t> chunks;
    uint32_t last_count = kChunkRays;  // rays in the last chunk
    uint32_t rays = 0;
  };
  uint32_t NewChunk();

  std::vector<uint32_t> queue_of_;  // by block id
  std::vector<Queue> queues_;
  std::vector<uint32_t> free_queues_;
  std::vector<std::unique_ptr<RayChunk>> chunks_;
  std::vector<uint32_t> free_chunks_;
  struct ReadyItem {
    uint16_t priority;
    uint64_t sequence;
    uint32_t queue;
    bool operator<(const ReadyItem& o) const {
      return priority != o.priority ? priority < o.priority : sequence < o.sequence;
    }
  };
  std::priority_queue<ReadyItem> ready_;
  uint64_t sequence_ = 0;
  uint64_t rays_ = 0, peak_rays_ = 0;
  uint64_t chunks_in_use_ = 0, peak_chunks_ = 0;
};

}  // namespace raystack::slave
