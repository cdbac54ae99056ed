#include "tools/bench/block_queue_tracer.h"

#include <utility>

namespace raystack::bench {

BlockQueueTracer::BlockQueueTracer(store::OctreeView octree,
                                   std::span<const store::BlockView> blocks)
    : octree_(octree), blocks_(blocks), queues_(blocks.size()) {}

// The full front-to-back leaf sequence at the ray's own tmax. StoreTracer walks the same
// sequence and only skips leaves whose entry lies beyond the best hit (an ancestor cell is
// entered no later than its leaves and was tested with a larger tmax), so applying that one
// rule while advancing reproduces its visits exactly.
void BlockQueueTracer::BuildPaths(std::span<const Ray> rays) {
  steps_.clear();
  path_end_.resize(rays.size());
  cursor_.resize(rays.size());
  for (size_t i = 0; i < rays.size(); ++i) {
    cursor_[i] = static_cast<uint32_t>(steps_.size());
    float tmax = rays[i].tmax;
    const RayBoxSetup setup(rays[i], octree_.magnitude());
    octree_.VisitLeaves(rays[i], setup, &tmax,
                        [&](uint32_t, const store::OctreeNode& leaf, float t_enter, float) {
                          // Blocks whose bounds (their BVH's root box) the ray misses are left
                          // out, as the store's walks leave them out; the leaf's first step
                          // counts the steps the leaf got.
                          const size_t first = steps_.size();
                          for (uint32_t b = leaf.first; b < leaf.first + leaf.count; ++b)
                            if (store::MayHit(setup, blocks_[b].bounds(), rays[i].tmin, tmax))
                              steps_.push_back({b, 0u, t_enter});
                          if (steps_.size() > first)
                            steps_[first].leaf_blocks = static_cast<uint32_t>(steps_.size() - first);
                          return true;
                        });
    path_end_[i] = static_cast<uint32_t>(steps_.size());
  }
}

void BlockQueueTracer::Enqueue(uint32_t ray, uint32_t block) {
  std::vector<uint32_t>& q = queues_[block];
  if (q.empty()) active_.push_back(block);
  q.push_back(ray);
}

void BlockQueueTracer::AdvanceClosest(uint32_t i, float best_t) {
  uint32_t c = cursor_[i] + 1;
  while (c < path_end_[i]) {
    const Step& s = steps_[c];
    if (s.leaf_blocks == 0 || !(s.t_enter > best_t * bvh_internal::kFarScale)) {
      cursor_[i] = c;
      Enqueue(i, s.block);
      return;
    }
    c += s.leaf_blocks;  // the whole leaf lies beyond the best hit
  }
}

void BlockQueueTracer::AdvanceAny(uint32_t i) {
  const uint32_t c = cursor_[i] + 1;
  if (c < path_end_[i]) {
    cursor_[i] = c;
    Enqueue(i, steps_[c].block);
  }
}

void BlockQueueTracer::Intersect(std::span<const Ray> rays, std::span<Hit> hits) {
  BuildPaths(rays);
  for (size_t i = 0; i < rays.size(); ++i) {
    hits[i] = Hit{};
    hits[i].t = rays[i].tmax;
    if (cursor_[i] < path_end_[i]) Enqueue(static_cast<uint32_t>(i), steps_[cursor_[i]].block);
  }
  while (!active_.empty()) {
    std::swap(active_, current_);
    active_.clear();
    for (const uint32_t b : current_) {
      std::swap(batch_ids_, queues_[b]);
      queues_[b].clear();
      const size_t n = batch_ids_.size();
      batch_rays_.resize(n);
      batch_hits_.resize(n);
      for (size_t k = 0; k < n; ++k) {
        batch_rays_[k] = rays[batch_ids_[k]];
        batch_hits_[k] = hits[batch_ids_[k]];
      }
      blocks_[b].IntersectBatch(batch_rays_, batch_hits_);
      ray_block_visits_ += n;
      ++batches_;
      for (size_t k = 0; k < n; ++k) {
        hits[batch_ids_[k]] = batch_hits_[k];
        AdvanceClosest(batch_ids_[k], batch_hits_[k].t);
      }
    }
  }
  for (Hit& h : hits) {
    if (!h.Valid()) h.t = std::numeric_limits<float>::infinity();
  }
}

void BlockQueueTracer::Occluded(std::span<const Ray> rays, std::span<uint8_t> occluded) {
  BuildPaths(rays);
  for (size_t i = 0; i < rays.size(); ++i) {
    occluded[i] = 0;
    if (cursor_[i] < path_end_[i]) Enqueue(static_cast<uint32_t>(i), steps_[cursor_[i]].block);
  }
  while (!active_.empty()) {
    std::swap(active_, current_);
    active_.clear();
    for (const uint32_t b : current_) {
      std::swap(batch_ids_, queues_[b]);
      queues_[b].clear();
      const size_t n = batch_ids_.size();
      batch_rays_.resize(n);
      batch_occluded_.resize(n);
      for (size_t k = 0; k < n; ++k) batch_rays_[k] = rays[batch_ids_[k]];
      blocks_[b].OccludedBatch(batch_rays_, batch_occluded_);
      ray_block_visits_ += n;
      ++batches_;
      for (size_t k = 0; k < n; ++k) {
        if (batch_occluded_[k]) {
          occluded[batch_ids_[k]] = 1;
        } else {
          AdvanceAny(batch_ids_[k]);
        }
      }
    }
  }
}

}  // namespace raystack::bench
