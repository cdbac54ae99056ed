// WideBvh's walks, one ray (wide_bvh_ray_walk.inc) and packets (wide_bvh_packet_walk.inc),
// compiled for the build's baseline (SSE2 on x86-64) and, on x86-64, once more for AVX2, chosen
// when the process first walks. AVX2 puts a node's 8 boxes, and 8 rays of a packet, in one
// register where SSE2 needs two: packets of 8 gained 17-20% on the dragon's primary rays, and
// packets of 16 (two registers) a further 9-17%; single rays: see wide_bvh_ray_walk.inc.
//
// Packets' results equal the single-ray walk's bit for bit: the bounds meet every box any of
// the rays meets there, the leaf tests are the single-ray ones lane by lane (the same float
// operations), and the closest-hit rule (CloserThan) does not depend on the order in which
// leaves are visited. Both copies of each walk make the same float operations.

#include <algorithm>
#include <atomic>
#include <bit>
#include <cstring>
#include <limits>
#include <utility>

#if defined(__SSE2__)  // every x86-64; elsewhere a packet's rays take the single-ray walk
#include <immintrin.h>
#endif

#include "common/base/check.h"
#include "common/geometry/next_float.h"
#include "common/geometry/triangle.h"
#include "common/geometry/wide_bvh.h"
#include "common/geometry/wide_bvh_internal.h"

// AVX2 code is compiled in a region of its own (#pragma GCC target), not with -mavx2 for the
// file: inline functions from headers are then emitted, where they are not inlined, for the
// build's baseline, so no AVX2 copy can be linked in their place elsewhere. GCC only: clang
// (the fuzzing build) has no such pragma and keeps the SSE2 walk.
#if defined(__SSE2__) && defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define RAYSTACK_HAS_WALK_AVX2 1
#else
#define RAYSTACK_HAS_WALK_AVX2 0
#endif

namespace raystack {

using wide_bvh_internal::BoxRay;
using wide_bvh_internal::Corners;

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

namespace {

#if defined(__SSE2__)
namespace sse2 {
#define RAYSTACK_WALK_AVX2 0
#include "common/geometry/wide_bvh_ray_walk.inc"
#include "common/geometry/wide_bvh_packet_walk.inc"
#undef RAYSTACK_WALK_AVX2
}  // namespace sse2
namespace baseline = sse2;
#else
namespace generic {  // the single-ray walk alone; a packet's rays take it one by one
#define RAYSTACK_WALK_AVX2 0
#include "common/geometry/wide_bvh_ray_walk.inc"
#undef RAYSTACK_WALK_AVX2
}  // namespace generic
namespace baseline = generic;
#endif

#if RAYSTACK_HAS_WALK_AVX2
#pragma GCC push_options
#pragma GCC target("avx2")
namespace avx2 {
#define RAYSTACK_WALK_AVX2 1
#include "common/geometry/wide_bvh_ray_walk.inc"
#include "common/geometry/wide_bvh_packet_walk.inc"
#undef RAYSTACK_WALK_AVX2
}  // namespace avx2
#pragma GCC pop_options
#endif

// Whether the walks take their AVX2 copies: the CPU has it (and the OS saves its registers),
// and AllowAvx2 has not turned it off.
std::atomic<bool> avx2_allowed{true};

bool UseAvx2() {
#if RAYSTACK_HAS_WALK_AVX2
  static const bool cpu_has_it = __builtin_cpu_supports("avx2");
  return cpu_has_it && avx2_allowed.load(std::memory_order_relaxed);
#else
  return false;
#endif
}

}  // namespace

bool WideBvh::Intersect(const Ray& ray, Hit* hit) const {
#if RAYSTACK_HAS_WALK_AVX2
  if (UseAvx2()) return avx2::IntersectRay(*this, ray, hit);
#endif
  return baseline::IntersectRay(*this, ray, hit);
}

bool WideBvh::Occluded(const Ray& ray) const {
#if RAYSTACK_HAS_WALK_AVX2
  if (UseAvx2()) return avx2::OccludedRay(*this, ray);
#endif
  return baseline::OccludedRay(*this, ray);
}

bool WideBvh::AllowAvx2(bool allowed) {
  avx2_allowed.store(allowed, std::memory_order_relaxed);
  return UseAvx2();
}

uint32_t WideBvh::IntersectPacket(std::span<const Ray> rays, std::span<Hit> hits) const {
  CHECK(hits.size() >= rays.size() && rays.size() <= static_cast<size_t>(kPacketSize));
#if RAYSTACK_HAS_WALK_AVX2
  if (UseAvx2()) return avx2::IntersectPacket(*this, rays, hits);
#endif
#if defined(__SSE2__)
  return sse2::IntersectPacket(*this, rays, hits);
#else
  uint32_t found = 0;
  for (size_t i = 0; i < rays.size(); ++i) found |= uint32_t{Intersect(rays[i], &hits[i])} << i;
  return found;
#endif
}

uint32_t WideBvh::OccludedPacket(std::span<const Ray> rays) const {
  CHECK(rays.size() <= static_cast<size_t>(kPacketSize));
#if RAYSTACK_HAS_WALK_AVX2
  if (UseAvx2()) return avx2::OccludedPacket(*this, rays);
#endif
#if defined(__SSE2__)
  return sse2::OccludedPacket(*this, rays);
#else
  uint32_t occluded = 0;
  for (size_t i = 0; i < rays.size(); ++i) occluded |= uint32_t{Occluded(rays[i])} << i;
  return occluded;
#endif
}

}  // namespace raystack
