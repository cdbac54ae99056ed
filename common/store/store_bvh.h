#pragma once
// Every triangle of a store in one WideBvh, for models that fit in memory: the same closest and
// any hits as StoreTracer (bit for bit: t, u, v and the source triangle), without the octree
// walk and the per-block trees. A triangle that crosses cells is stored in several blocks;
// here it is kept once, and a hit names the first block holding it (by block id) and its
// index there. The copies are the same triangle with the same attributes, so shading from
// either gives the same result. Read-only after construction: queries may run on several
// threads at once.

#include <cstdint>
#include <span>
#include <vector>

#include "common/geometry/wide_bvh.h"
#include "common/geometry/ray.h"
#include "common/store/block_view.h"

namespace raystack::store {

class StoreBvh {
 public:
  // `blocks[id]` is block `id`, every one of them parsed; they need not outlive this. The tree
  // is built on `threads` threads, and does not depend on how many.
  explicit StoreBvh(std::span<const BlockView> blocks, int threads = 1);

  // As StoreTracer::Intersect: the closest hit in (ray.tmin, ray.tmax], invalid on a miss.
  Hit Intersect(const Ray& ray) const;
  // As BlockView::Intersect over every block: the closest hit in (ray.tmin, hit->t], ties
  // broken by CloserThan; on a closer one, fills `hit` (block and index of a copy included)
  // and returns true.
  bool Intersect(const Ray& ray, Hit* hit) const { return bvh_.Intersect(ray, hit); }
  // As StoreTracer::Occluded: anything in (ray.tmin, ray.tmax).
  bool Occluded(const Ray& ray) const { return bvh_.Occluded(ray); }
  // The same for up to WideBvh::kPacketSize coherent rays at once (see WideBvh): bit i of the
  // result set when hits[i] was replaced, or rays[i] is occluded.
  uint32_t IntersectPacket(std::span<const Ray> rays, std::span<Hit> hits) const {
    return bvh_.IntersectPacket(rays, hits);
  }
  uint32_t OccludedPacket(std::span<const Ray> rays) const { return bvh_.OccludedPacket(rays); }

  size_t triangle_count() const { return bvh_.triangle_count(); }
  size_t bytes() const { return bvh_.bytes(); }

 private:
  WideBvh bvh_;
};

}  // namespace raystack::store
