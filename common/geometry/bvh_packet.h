#pragma once
// Packet traversal of the in-block BVH: up to 4 rays whose directions share a sign octant go
// down the tree together, one SSE lane per ray for the box tests. Rays of one octant visit
// the children of every node in the same order (near child first along the node's axis), so
// each ray meets its nodes in exactly the order TraverseBvh would give it, each box test is
// the same IEEE operations on the same operands (with the ray's own tmax at that moment),
// and each leaf is handed to the caller per ray in that same order: the results are those of
// TraverseBvh, bit for bit. The gain is one node fetch and one vector box test for 4 rays.
// Portable: SSE2 is the x86-64 baseline; other targets fall back to one ray at a time.

#include <cstdint>
#include <span>

#include "common/base/check.h"
#include "common/geometry/bvh.h"
#include "common/geometry/ray.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace raystack {

inline constexpr int kPacketWidth = 4;

// The sign octant as RayBoxSetup defines it (bit a set when 1 / direction[a] < 0, so a zero
// component counts with the sign of its zero). Rays of one packet must share it.
inline int DirectionOctant(const Ray& ray) {
  int octant = 0;
  for (int a = 0; a < 3; ++a) octant |= (1.0f / ray.direction[a] < 0 ? 1 : 0) << a;
  return octant;
}

// Box-test constants of a packet, one lane per ray, SoA. Unused lanes are masked off by the
// caller's `lanes` mask and hold copies of lane 0 (finite, harmless).
struct alignas(16) RayPacket4 {
  float origin[3][kPacketWidth];
  float inv_dir[3][kPacketWidth];
  float pad[3][kPacketWidth];
  float tmin[kPacketWidth];
  int dir_is_neg[3];  // shared by every lane

  // `rays[0..count)` must share DirectionOctant. `magnitude`: as RayBoxSetup's.
  RayPacket4(const Ray* const* rays, int count, float magnitude);
};
static_assert(sizeof(RayPacket4) % 16 == 0);

// Visits the leaves each lane in `lanes` (bit k = lane k) may hit, as TraverseBvh does per
// ray. `tmax[k]` is lane k's current limit (the caller's leaf function may lower it);
// `leaf(k, first, count)` tests primitives for lane k and returns true when that lane is
// done (any-hit), which drops it from the rest of the traversal.
template <typename LeafFn>
void TraverseBvhPacket4(std::span<const BvhNode> nodes, const RayPacket4& packet, int lanes,
                        float* tmax, LeafFn&& leaf);

// ---------------------------------------------------------------------------------------

inline RayPacket4::RayPacket4(const Ray* const* rays, int count, float magnitude) {
  DCHECK(count >= 1 && count <= kPacketWidth);
  for (int k = 0; k < kPacketWidth; ++k) {
    const RayBoxSetup s(*rays[k < count ? k : 0], magnitude);  // the very constants TraverseBvh uses
    for (int a = 0; a < 3; ++a) {
      origin[a][k] = s.origin[a];
      inv_dir[a][k] = s.inv_dir[a];
      pad[a][k] = s.pad[a];
      if (k == 0) dir_is_neg[a] = s.dir_is_neg[a];
    }
    tmin[k] = rays[k < count ? k : 0]->tmin;
  }
}

namespace bvh_internal {

#if defined(__SSE2__)
// IntersectBox for 4 lanes at once: the same operations in the same order per lane
// (max/min written as IntersectBox's selects, which is what maxps/minps compute, NaN
// included). Returns the mask of lanes whose interval meets the box.
inline int IntersectBox4(const RayPacket4& p, const BvhNode& node, __m128 tmax) {
  const __m128 far_scale = _mm_set1_ps(kFarScale);
  __m128 t0 = _mm_load_ps(p.tmin);
  __m128 t1 = _mm_mul_ps(tmax, far_scale);
  for (int a = 0; a < 3; ++a) {
    const float near_plane = p.dir_is_neg[a] ? node.upper[a] : node.lower[a];
    const float far_plane = p.dir_is_neg[a] ? node.lower[a] : node.upper[a];
    const __m128 o = _mm_load_ps(p.origin[a]);
    const __m128 inv = _mm_load_ps(p.inv_dir[a]);
    const __m128 pad = _mm_load_ps(p.pad[a]);
    const __m128 t_near = _mm_sub_ps(_mm_mul_ps(_mm_sub_ps(_mm_set1_ps(near_plane), o), inv), pad);
    const __m128 t_far = _mm_add_ps(
        _mm_mul_ps(_mm_mul_ps(_mm_sub_ps(_mm_set1_ps(far_plane), o), inv), far_scale), pad);
    t0 = _mm_max_ps(t_near, t0);  // t_near > t0 ? t_near : t0
    t1 = _mm_min_ps(t_far, t1);   // t_far < t1 ? t_far : t1
  }
  return _mm_movemask_ps(_mm_cmpngt_ps(t0, t1));  // !(t0 > t1)
}
#else
inline int IntersectBox4(const RayPacket4& p, const BvhNode& node, const float* tmax) {
  int mask = 0;
  for (int k = 0; k < kPacketWidth; ++k) {
    RayBoxSetup s(Ray{}, 0);
    for (int a = 0; a < 3; ++a) {
      s.origin[a] = p.origin[a][k];
      s.inv_dir[a] = p.inv_dir[a][k];
      s.pad[a] = p.pad[a][k];
      s.dir_is_neg[a] = p.dir_is_neg[a];
    }
    float t_enter;
    if (IntersectBox(s, node.lower, node.upper, p.tmin[k], tmax[k], &t_enter)) mask |= 1 << k;
  }
  return mask;
}
#endif

}  // namespace bvh_internal

template <typename LeafFn>
void TraverseBvhPacket4(std::span<const BvhNode> nodes, const RayPacket4& packet, int lanes,
                        float* tmax, LeafFn&& leaf) {
  if (nodes.empty() || lanes == 0) return;
  struct Entry {
    uint32_t node;
    int lanes;  // lanes that met the parent, so must test this node
  };
  Entry stack[kBvhMaxDepth];
  int size = 0;
  uint32_t index = 0;
  int active = lanes;
  int done = 0;  // lanes finished by their leaf function
  while (true) {
    const BvhNode& node = nodes[index];
#if defined(__SSE2__)
    const int hit = active & bvh_internal::IntersectBox4(packet, node, _mm_loadu_ps(tmax));
#else
    const int hit = active & bvh_internal::IntersectBox4(packet, node, tmax);
#endif
    if (hit) {
      if (node.count == 0) {
        uint32_t near_child = index + 1;
        uint32_t far_child = node.offset;
        if (packet.dir_is_neg[node.axis]) std::swap(near_child, far_child);
        DCHECK(size < kBvhMaxDepth);
        __builtin_prefetch(&nodes[far_child]);  // as TraverseBvh: fetched while the near side is walked
        stack[size++] = {far_child, hit};
        index = near_child;
        active = hit;
        continue;
      }
      for (int k = 0; k < kPacketWidth; ++k) {
        if ((hit >> k) & 1) {
          if (leaf(k, node.offset, static_cast<uint32_t>(node.count))) done |= 1 << k;
        }
      }
    }
    do {
      if (size == 0) return;
      --size;
      index = stack[size].node;
      active = stack[size].lanes & ~done;
    } while (active == 0);
  }
}

}  // namespace raystack
