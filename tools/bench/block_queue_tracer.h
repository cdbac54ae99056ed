#pragma once
// In-core tracing the way the renderer's ray stack does it: each ray waits in the queue of
// the next block it must visit, and a block's queue is traced as one batch
// (BlockView::IntersectBatch / OccludedBatch). Each ray visits the same blocks, in the same
// order and with the same stopping rule as StoreTracer, so the hits are bit-identical to it;
// only the grouping differs. A benchmark's stand-in for the ray stack, with every block in
// memory. Scratch is kept between calls (no allocation once warm). Not thread-safe: one per
// thread.

#include <cstdint>
#include <span>
#include <vector>

#include "common/geometry/ray.h"
#include "common/store/block_view.h"
#include "common/store/octree.h"

namespace raystack::bench {

class BlockQueueTracer {
 public:
  // `blocks[id]` is block `id`, every one of them parsed and kept alive by the caller.
  BlockQueueTracer(store::OctreeView octree, std::span<const store::BlockView> blocks);

  // Closest hits: hits[i] as StoreTracer::Intersect(rays[i]) would return it.
  void Intersect(std::span<const Ray> rays, std::span<Hit> hits);
  // Any hit: occluded[i] as StoreTracer::Occluded(rays[i]).
  void Occluded(std::span<const Ray> rays, std::span<uint8_t> occluded);

  // Rays traced and batches run since construction (their ratio is the mean batch size).
  uint64_t ray_block_visits() const { return ray_block_visits_; }
  uint64_t batches() const { return batches_; }

 private:
  // One block on a ray's path. The first block of an octree leaf carries the leaf's entry
  // distance and block count: the whole leaf is skipped once the best hit is nearer.
  struct Step {
    uint32_t block;
    uint32_t leaf_blocks;  // blocks in the leaf for its first block, else 0
    float t_enter;
  };

  void BuildPaths(std::span<const Ray> rays);
  void Enqueue(uint32_t ray, uint32_t block);
  // Moves ray `i` past its current step to the next block it must visit, if any.
  void AdvanceClosest(uint32_t i, float best_t);
  void AdvanceAny(uint32_t i);

  store::OctreeView octree_;
  std::span<const store::BlockView> blocks_;
  std::vector<Step> steps_;
  std::vector<uint32_t> path_end_;  // per ray: one past its last step
  std::vector<uint32_t> cursor_;    // per ray: its current step
  std::vector<std::vector<uint32_t>> queues_;  // per block: waiting rays
  std::vector<uint32_t> active_, current_;     // blocks with a non-empty queue
  std::vector<uint32_t> batch_ids_;
  std::vector<Ray> batch_rays_;
  std::vector<Hit> batch_hits_;
  std::vector<uint8_t> batch_occluded_;
  uint64_t ray_block_visits_ = 0;
  uint64_t batches_ = 0;
};

}  // namespace raystack::bench
