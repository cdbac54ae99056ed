#pragma once
// What WideBvh's single-ray and packet walks share: a ray's box-test constants with the
// margin that keeps them conservative, the stack bound, and a leaf lane's corners. Internal to
// common/geometry/wide_bvh*.cpp.

#include <algorithm>
#include <bit>
#include <cstddef>
#include <cmath>
#include <cstdint>

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

// A ray's constants for the box tests: IntersectBox's, with the rows of Node::box that hold
// each axis's near and far planes, and a margin in t per axis.
//
// The margin: IntersectTriangle decides inside or outside in float, relative to the ray's
// origin, so it accepts rays that pass outside a triangle by a few ulps of the coordinates'
// magnitude. Such a hit can lie before the entry into the triangle's (tight) box, and pruning
// by the best hit would then cull the box (found on the conference room: a hit 7e-7 before
// its leaf's computed entry, 7 ulps of the coordinates in space). Every box is therefore
// widened in space by 2^-17 of the largest magnitude among the ray's origin and the model (64
// to 128 ulps), turned into distances along each axis (`pad`). It costs 7-10% of the rays/s.
struct BoxRay {
  float origin[3], inv_dir[3], pad[3];
  int near_row[3], far_row[3];

  BoxRay() = default;  // for arrays filled later (packets)
  BoxRay(const Ray& ray, float model_magnitude) {
    float magnitude = model_magnitude;
    for (int a = 0; a < 3; ++a) magnitude = std::max(magnitude, std::fabs(ray.origin[a]));
    const float margin = 2 * magnitude * 0x1p-18f;
    for (int a = 0; a < 3; ++a) {
      origin[a] = ray.origin[a];
      inv_dir[a] = 1.0f / ray.direction[a];
      const bool negative = inv_dir[a] < 0;
      near_row[a] = negative ? 3 + a : a;
      far_row[a] = negative ? a : 3 + a;
      // A ray parallel to the slabs (infinite inv_dir) keeps IntersectBox's exact test.
      pad[a] = std::isinf(inv_dir[a]) ? 0.0f : margin * std::fabs(inv_dir[a]);
    }
  }
};

// Stack entries: a wide node pushes at most kWidth - 1, and the tree is no deeper than the
// binary one.
constexpr int kStackSize = (WideBvh::kWidth - 1) * kBvhMaxDepth + 1;

// Triangle k's corners in a leaf's lane-by-lane layout.
inline void Corners(const float (&p)[3][3][4], uint32_t k, Vec3f* p0, Vec3f* p1, Vec3f* p2) {
  *p0 = {p[0][0][k], p[0][1][k], p[0][2][k]};
  *p1 = {p[1][0][k], p[1][1][k], p[1][2][k]};
  *p2 = {p[2][0][k], p[2][1][k], p[2][2][k]};
}

}  // namespace wide_bvh_internal
}  // namespace raystack
