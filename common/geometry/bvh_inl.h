#pragma once
// Inline bodies for bvh.h: the per-ray box test and the traversal loop run once per node
// visited, so they must inline into the caller's leaf function. Include bvh.h, not this file.

#include <cstdint>
#include <limits>
#include <span>
#include <utility>

#include "common/base/check.h"
#include "common/geometry/bvh.h"

namespace raystack {

namespace bvh_internal {

// pbrt-v4's gamma(3): bounds the relative error of (plane - origin) * inv_dir, three roundings.
inline constexpr float kGamma3 = 3.0f * 0x1p-24f / (1.0f - 3.0f * 0x1p-24f);
// Ize 2013: enlarging the far distance by 2 * gamma(3) keeps every box the exact ray meets.
inline constexpr float kFarScale = 1.0f + 2.0f * kGamma3;

}  // namespace bvh_internal

// A zero direction component gives inv_dir = +inf or -inf (the sign of the zero), which keeps
// the slab distances of that axis at +-inf, and the sign picks which plane is near.
inline RayBoxSetup::RayBoxSetup(const Ray& ray, float magnitude) : origin(ray.origin) {
  for (int a = 0; a < 3; ++a) {
    inv_dir[a] = 1.0f / ray.direction[a];
    dir_is_neg[a] = inv_dir[a] < 0 ? 1 : 0;
  }
  BoxMarginPads(ray, inv_dir, magnitude, pad);
}

inline bool IntersectBox(const RayBoxSetup& s, const float lower[3], const float upper[3],
                         float tmin, float tmax, float* t_enter) {
  // The caller's tmax may be a hit distance found in a sibling box. A primitive in this box
  // can tie with it (coplanar duplicates) while rounding puts this box's entry an ulp or two
  // past it, so the limit gets the same slack as the far planes.
  float t0 = tmin;
  float t1 = tmax * bvh_internal::kFarScale;
  for (int a = 0; a < 3; ++a) {
    const float near_plane = s.dir_is_neg[a] ? upper[a] : lower[a];
    const float far_plane = s.dir_is_neg[a] ? lower[a] : upper[a];
    const float t_near = (near_plane - s.origin[a]) * s.inv_dir[a] - s.pad[a];
    const float t_far = (far_plane - s.origin[a]) * s.inv_dir[a] * bvh_internal::kFarScale + s.pad[a];
    // 0 * inf = NaN happens only for a ray lying in a slab plane, which is inside the closed
    // slab: the comparisons are written so a NaN leaves the interval unchanged.
    t0 = t_near > t0 ? t_near : t0;
    t1 = t_far < t1 ? t_far : t1;
  }
  if (t0 > t1) return false;
  *t_enter = t0;
  return true;
}

template <typename LeafFn>
void TraverseBvh(std::span<const BvhNode> nodes, const Ray& ray, float magnitude, float* tmax,
                 LeafFn&& leaf) {
  if (nodes.empty()) return;
  const RayBoxSetup setup(ray, magnitude);
  uint32_t stack[kBvhMaxDepth];
  int size = 0;
  uint32_t index = 0;
  while (true) {
    const BvhNode& node = nodes[index];
    float t_enter;
    // Tested when popped rather than when pushed, so a hit found meanwhile prunes the box.
    if (IntersectBox(setup, node.lower, node.upper, ray.tmin, *tmax, &t_enter)) {
      if (node.count == 0) {
        uint32_t near_child = index + 1;
        uint32_t far_child = node.offset;
        if (setup.dir_is_neg[node.axis]) std::swap(near_child, far_child);
        DCHECK(size < kBvhMaxDepth);
        // The near child usually shares the parent's cache line (depth-first layout); the far
        // one is fetched now, while the near subtree is walked (node loads miss the cache more
        // than anything else in a block's traversal).
        __builtin_prefetch(&nodes[far_child]);
        stack[size++] = far_child;
        index = near_child;
        continue;
      }
      if (leaf(node.offset, static_cast<uint32_t>(node.count))) return;
    }
    if (size == 0) return;
    index = stack[--size];
  }
}

}  // namespace raystack
