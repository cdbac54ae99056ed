#pragma once
// A binary BVH over a few thousand primitives (one block's worth), built with binned SAH.
// Nodes are 32-byte PODs in depth-first order, stored as-is inside blocks on disk, so a
// decompressed block is traversed in place. Building allocates; traversal never does.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include "common/geometry/bounds.h"
#include "common/geometry/ray.h"

namespace raystack {

struct BvhNode {
  float lower[3];
  float upper[3];
  uint32_t offset;  // inner: index of the second child (the first is this + 1); leaf: first primitive
  uint16_t count;   // 0 for an inner node, else the number of primitives in the leaf
  uint8_t axis;     // inner: split axis, used to visit the near child first
  uint8_t pad;
};
static_assert(sizeof(BvhNode) == 32, "BvhNode is stored on disk");

inline Bounds3f NodeBounds(const BvhNode& n) {
  return {{n.lower[0], n.lower[1], n.lower[2]}, {n.upper[0], n.upper[1], n.upper[2]}};
}

// Traversal keeps a fixed stack of this many entries, so the builder guarantees that no leaf
// is deeper than this (root at depth 0). 64 levels hold any tree over 2^32 primitives even
// when half of them come from median splits forced by the bound.
inline constexpr int kBvhMaxDepth = 64;

// Upper bound on BvhBuildOptions::bins: the bins live on the builder's stack.
inline constexpr int kBvhMaxBins = 64;

struct BvhBuildPrimitive {
  Bounds3f bounds;  // may be clipped to a cell: tighter than the primitive's own box
};

struct BvhBuildOptions {
  int max_leaf_size = 4;  // leaves hold at most this many primitives (1..65535)
  int bins = 16;          // SAH bins per axis (2..kBvhMaxBins)
  float traversal_cost = 1.0f;
  float intersection_cost = 1.0f;
  // Threads that build subtrees at once, for trees of at least 65,536 primitives (smaller
  // ones are built on the calling thread). The tree does not depend on it.
  int threads = 1;
};

// Builds the BVH. On return, leaf primitives are `order[offset .. offset + count)`, where
// `order` is a permutation of 0..prims.size()-1. Empty input gives no nodes. Deterministic:
// the same input gives the same nodes. Terminates on degenerate input (all boxes equal, zero
// extent): such sets are split by index. Primitive bounds must be non-empty and finite (the
// importer rejects NaN and Inf); zero extent is fine. No leaf is deeper than kBvhMaxDepth.
std::vector<BvhNode> BuildBvh(std::span<const BvhBuildPrimitive> prims,
                              const BvhBuildOptions& options, std::vector<uint32_t>* order);

// The margin every box test that guards triangles needs, as distances along each axis.
//
// IntersectTriangle decides inside or outside in float, relative to the ray's origin, so it
// accepts rays that pass outside a triangle by a few ulps of the coordinates' magnitude. Such a
// hit can lie before the entry into the triangle's tight box, or outside it altogether, and a
// box test would then cull the box, or pruning by a farther hit found first would (found on the
// conference room: a hit 7e-7 before its box's computed entry, 7 ulps of the coordinates in
// space; every binary tree over those 5 triangles then returned the farther hit). Boxes are
// therefore widened in space by 2^-17 of the largest magnitude among the ray's origin and the
// triangles the box may hold (`magnitude`; 64 to 128 ulps), turned into distances along each
// axis. A ray parallel to an axis (infinite 1 / direction) keeps the exact test on it.
// WideBvh's packets compute the same across their lanes (RayLanes, wide_bvh_packet_walk.inc):
// a change here must be made there too.
inline void BoxMarginPads(const Ray& ray, Vec3f inv_dir, float magnitude, float pad[3]) {
  float m = magnitude;
  for (int a = 0; a < 3; ++a) m = std::max(m, std::fabs(ray.origin[a]));
  const float margin = 2 * m * 0x1p-18f;
  for (int a = 0; a < 3; ++a) pad[a] = std::isinf(inv_dir[a]) ? 0.0f : margin * std::fabs(inv_dir[a]);
}

// Per-ray constants for box tests. `magnitude`: the largest |coordinate| of any vertex of the
// triangles the tested boxes hold (a block's, a model's), for the margin (BoxMarginPads).
struct RayBoxSetup {
  Vec3f origin;
  Vec3f inv_dir;
  int dir_is_neg[3];
  float pad[3];

  RayBoxSetup(const Ray& ray, float magnitude);
};

// Slab test, robust in the sense of Ize 2013: the far distance is enlarged by 2 ulp-ish so a ray
// grazing a box edge is never culled by rounding, and both by the setup's margin. Returns true
// if [tmin, tmax] meets the box so widened.
bool IntersectBox(const RayBoxSetup& s, const float lower[3], const float upper[3], float tmin,
                  float tmax, float* t_enter);

// Visits the leaves a ray may hit, near child first. `leaf(first, count)` tests primitives
// [first, first + count) and returns true to stop the traversal (any-hit). It may lower
// `*tmax` (closest-hit) so farther subtrees are pruned. `magnitude`: as RayBoxSetup's.
template <typename LeafFn>
void TraverseBvh(std::span<const BvhNode> nodes, const Ray& ray, float magnitude, float* tmax,
                 LeafFn&& leaf);

}  // namespace raystack

#include "common/geometry/bvh_inl.h"
