#pragma once
// The copies of WideBvh's walks, one ray (wide_bvh_ray_walk.inc) and packets
// (wide_bvh_packet_walk.inc), one per instruction set, each compiled in a file of its own:
// wide_bvh_walks_baseline.cpp (the build's baseline: SSE2 on x86-64), wide_bvh_walks_avx2.cpp
// and wide_bvh_walks_avx512.cpp. wide_bvh_walks.cpp chooses one when the process first walks.
// One file each, not one file for all: in one translation unit the three copies outgrew GCC's
// inlining budget for the unit, and IntersectTriangle, PushChildren and the like were called
// out of line, in their baseline compilation (the dragon's rays 10-20% slower).
//
// AVX2 code is compiled in regions of its own (#pragma GCC target), not with -mavx2 for its
// file: inline functions from headers are then emitted, where they are not inlined, for the
// build's baseline, so no AVX2 copy can be linked in their place elsewhere. GCC only: clang
// (the fuzzing build) has no such pragma and keeps the baseline walks. So this header also
// includes everything the walks use, for the copies to include before their region begins.

#include <algorithm>
#include <bit>
#include <cstdint>
#include <cstring>
#include <limits>
#include <span>
#include <utility>

#if defined(__SSE2__)
#include <immintrin.h>
#endif

#include "common/base/check.h"
#include "common/geometry/next_float.h"
#include "common/geometry/ray.h"
#include "common/geometry/triangle.h"
#include "common/geometry/wide_bvh.h"
#include "common/geometry/wide_bvh_internal.h"

#if defined(__SSE2__) && defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define RAYSTACK_HAS_WALK_AVX2 1
#else
#define RAYSTACK_HAS_WALK_AVX2 0
#endif

namespace raystack {

// What the walks need of WideBvh's insides.
class WideBvhWalks {
 public:
  using Node = WideBvh::Node;
  using Leaf = WideBvh::Leaf;
  static const Leaf& LeafAt(const WideBvh& bvh, uint32_t group) { return bvh.leaves_[group]; }
  static float Magnitude(const WideBvh& bvh) { return bvh.magnitude_; }
  static float Extent(const WideBvh& bvh) { return bvh.extent_; }
  template <typename NodeHitsFn, typename LeafFn>
  __attribute__((always_inline)) static void Traverse(const WideBvh& bvh, NodeHitsFn&& node_hits,
                                                      const float* tmax, LeafFn&& leaf) {
    bvh.Traverse(node_hits, tmax, leaf);
  }
};

// Each copy's entry points: WideBvh::Intersect, Occluded, IntersectPacket and OccludedPacket.
namespace walks_baseline {
bool Intersect(const WideBvh& bvh, const Ray& ray, Hit* hit);
bool Occluded(const WideBvh& bvh, const Ray& ray);
uint32_t IntersectPackets(const WideBvh& bvh, std::span<const Ray> rays, std::span<Hit> hits);
uint32_t OccludedPackets(const WideBvh& bvh, std::span<const Ray> rays);
}  // namespace walks_baseline

#if RAYSTACK_HAS_WALK_AVX2
namespace walks_avx2 {  // 8 lanes a register
bool Intersect(const WideBvh& bvh, const Ray& ray, Hit* hit);
bool Occluded(const WideBvh& bvh, const Ray& ray);
uint32_t IntersectPackets(const WideBvh& bvh, std::span<const Ray> rays, std::span<Hit> hits);
uint32_t OccludedPackets(const WideBvh& bvh, std::span<const Ray> rays);
}  // namespace walks_avx2

namespace walks_avx512 {  // the AVX2 code, with AVX-512's instructions allowed
bool Intersect(const WideBvh& bvh, const Ray& ray, Hit* hit);
bool Occluded(const WideBvh& bvh, const Ray& ray);
uint32_t IntersectPackets(const WideBvh& bvh, std::span<const Ray> rays, std::span<Hit> hits);
uint32_t OccludedPackets(const WideBvh& bvh, std::span<const Ray> rays);
}  // namespace walks_avx512
#endif

}  // namespace raystack
