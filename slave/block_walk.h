#pragma once
// A waiting ray remembers how far it got as a count of blocks already traversed; the next
// block is found again by walking the in-RAM level-1 octree front to back. The walk is a pure
// function of (ray, closest hit so far, count), so a resumed ray visits exactly the blocks an
// uninterrupted one would, in the same order, whatever happened in between. Shrinking the
// closest hit only drops blocks from the end of the order (cells along a ray are entered in
// order), so the count stays valid.

#include <cstdint>

#include "common/geometry/ray.h"
#include "common/store/octree.h"

namespace raystack::slave {

// Id of the block at position `cursor` along `ray` before `tmax`, or kInvalidId.
inline uint32_t NthBlockAlong(const store::OctreeView& octree, const Ray& ray, float tmax,
                              uint32_t cursor) {
  uint32_t seen = 0, found = kInvalidId;
  float bound = tmax;
  octree.VisitLeaves(ray, &bound, [&](uint32_t, const store::OctreeNode& leaf, float, float) {
    if (cursor < seen + leaf.count) {
      found = leaf.first + (cursor - seen);
      return false;
    }
    seen += leaf.count;
    return true;
  });
  return found;
}

}  // namespace raystack::slave
