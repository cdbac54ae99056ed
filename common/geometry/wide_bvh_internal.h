#pragma once
// What WideBvh's single-ray and packet walks share: the walk itself, a ray's box-test
// constants with the margin that keeps them conservative, and a leaf lane's corners. Internal to
// common/geometry/wide_bvh*.cpp.

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cmath>
#include <cstdint>

#include "common/base/check.h"
#include "common/geometry/bvh.h"
#include "common/geometry/ray.h"
#include "common/geometry/vec.h"
#include "common/geometry/wide_bvh.h"

namespace raystack {

// Requests every cache line of the boxes the ray meets at once, so their misses overlap
// instead of following one another as the traversal reaches each line (node and leaf loads
// are most of a query's stalls on a model larger than the cache).
inline void WideBvh::Prefetch(const uint32_t child[kWidth], uint32_t mask) const {
  for (; mask; mask &= mask - 1) {
    const uint32_t ref = child[std::countr_zero(mask)];
    const char* p = (ref & kLeaf) ? reinterpret_cast<const char*>(&leaves_[(ref & ~kLeaf) >> 2])
                                  : reinterpret_cast<const char*>(&nodes_[ref]);
    const size_t bytes = (ref & kLeaf) ? sizeof(Leaf) : sizeof(Node);
    for (size_t line = 0; line < bytes; line += 64) __builtin_prefetch(p + line);
  }
}

namespace wide_bvh_internal {

// One entry of the traversal stack: a child reference and where the ray (or, for a packet, the
// nearest of its rays) enters its box.
struct Pending {
  uint32_t ref;
  float t_enter;
};

// Stack entries: a wide node pushes at most kWidth - 1, and the tree is no deeper than the
// binary one.
constexpr int kStackSize = (WideBvh::kWidth - 1) * kBvhMaxDepth + 1;

// Pushes the children in `mask` but the nearest, farthest first, and returns the nearest.
inline uint32_t PushChildren(const uint32_t child[WideBvh::kWidth], uint32_t mask,
                             const float t_enter[WideBvh::kWidth], Pending* stack, int* size) {
  const uint32_t rest = mask & (mask - 1);
  if ((rest & (rest - 1)) == 0) {  // two children, the most common case: no sort
    const int a = std::countr_zero(mask), b = std::countr_zero(rest);
    const bool a_nearer = t_enter[a] < t_enter[b];  // as the sort below: a tie returns b
    const int near = a_nearer ? a : b, far = a_nearer ? b : a;
    stack[(*size)++] = {child[far], t_enter[far]};
    return child[near];
  }
  Pending hit[WideBvh::kWidth];
  int n = 0;
  for (; mask; mask &= mask - 1) {  // insertion sort by entry, nearest last
    const int k = std::countr_zero(mask);
    int j = n++;
    for (; j > 0 && hit[j - 1].t_enter < t_enter[k]; --j) hit[j] = hit[j - 1];
    hit[j] = {child[k], t_enter[k]};
  }
  DCHECK(*size + n - 1 <= kStackSize);
  for (int j = 0; j < n - 1; ++j) stack[(*size)++] = hit[j];
  return hit[n - 1].ref;
}

}  // namespace wide_bvh_internal

// The walk every query shares, one ray or a packet: nodes nearest child first, the others kept
// with their entry distance. `node_hits(node, tmax, t_enter)` says which of a node's boxes are
// met within tmax and where each is entered (a ray's test, or a packet's bounds).
// `leaf(group, n)` tests leaf `group`'s n triangles, may lower `*tmax` (closest hit), and
// returns true to stop (any hit). A pending box the best hit has since passed is dropped when
// popped. Forced inline: as a call, the best hit's distance lives in memory behind `tmax` and
// primary rays lose 2%.
template <typename NodeHitsFn, typename LeafFn>
__attribute__((always_inline)) inline void WideBvh::Traverse(NodeHitsFn&& node_hits,
                                                          const float* tmax,
                                                          LeafFn&& leaf) const {
  using wide_bvh_internal::Pending;
  using wide_bvh_internal::PushChildren;
  if (nodes_.empty()) return;
  Pending stack[wide_bvh_internal::kStackSize];
  int size = 0;
  uint32_t ref = 0;
  while (true) {
    if (!(ref & kLeaf)) {
      const Node& node = nodes_[ref];
      float t_enter[kWidth];
      const uint32_t mask = node_hits(node, *tmax, t_enter) & node.occupied;
      if (mask != 0) {
        Prefetch(node.child, mask);
        ref = (mask & (mask - 1)) == 0 ? node.child[std::countr_zero(mask)]
                                       : PushChildren(node.child, mask, t_enter, stack, &size);
        continue;
      }
    } else if (leaf((ref & ~kLeaf) >> 2, (ref & 3u) + 1)) {
      return;
    }
    do {
      if (size == 0) return;
      ref = stack[--size].ref;
    } while (stack[size].t_enter > *tmax * bvh_internal::kFarScale);
  }
}

namespace wide_bvh_internal {

// A ray's constants for the box tests: IntersectBox's, with the rows of Node::box that hold
// each axis's near and far planes, and the margin of every box test that guards triangles
// (BoxMarginPads, with the model's magnitude). The margin costs 7-10% of the rays/s.
struct BoxRay {
  float origin[3], inv_dir[3], pad[3];
  int near_row[3], far_row[3];

  BoxRay() = default;  // for arrays filled later (packets)
  BoxRay(const Ray& ray, float model_magnitude) {
    Vec3f inv;
    for (int a = 0; a < 3; ++a) {
      origin[a] = ray.origin[a];
      inv[a] = inv_dir[a] = 1.0f / ray.direction[a];
      const bool negative = inv_dir[a] < 0;
      near_row[a] = negative ? 3 + a : a;
      far_row[a] = negative ? a : 3 + a;
    }
    BoxMarginPads(ray, inv, model_magnitude, pad);
  }
};

// Triangle k's corners in a leaf's lane-by-lane layout.
inline void Corners(const float (&p)[3][3][4], uint32_t k, Vec3f* p0, Vec3f* p1, Vec3f* p2) {
  *p0 = {p[0][0][k], p[0][1][k], p[0][2][k]};
  *p1 = {p[1][0][k], p[1][1][k], p[1][2][k]};
  *p2 = {p[2][0][k], p[2][1][k], p[2][2][k]};
}

}  // namespace wide_bvh_internal
}  // namespace raystack
