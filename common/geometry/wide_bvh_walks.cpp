// WideBvh's walks: which copy runs (wide_bvh_walk_copies.h). The widest the CPU has, chosen when
// the process first walks: AVX2 puts a node's 8 boxes, and 8 rays of a packet, in one register
// where SSE2 needs two (packets of 8 gained 17-20% on the dragon's primary rays, and packets of
// 16 in two registers a further 9-17%; single rays: see wide_bvh_ray_walk.inc). With AVX-512's
// instructions (and BMI) allowed, the same code's packets gained 1-2% on the dragon and 1-11% on
// the conference room (AMD Zen 4, embree_bench --walks avx2 against avx512, alternated;
// tools/bench/RESULTS.md).
//
// Packets' results equal the single-ray walk's bit for bit: the bounds meet every box any of
// the rays meets there, the leaf tests are the single-ray ones lane by lane (the same float
// operations), and the closest-hit rule (CloserThan) does not depend on the order in which
// leaves are visited. Every copy of each walk makes the same float operations (the build has
// -ffp-contract=off, so no copy fuses a multiply and an add).

#include <algorithm>
#include <atomic>

#include "common/base/check.h"
#include "common/geometry/wide_bvh.h"
#include "common/geometry/wide_bvh_walk_copies.h"

namespace raystack {
namespace {

using Isa = WideBvh::WalkIsa;

std::atomic<Isa> widest_allowed{Isa::kAvx512};  // LimitWalks'

// The widest copy the CPU has (libgcc's checks include that the OS saves its registers).
Isa CpuWalkIsa() {
#if RAYSTACK_HAS_WALK_AVX2
  const bool avx2 = __builtin_cpu_supports("avx2");
  if (avx2 && __builtin_cpu_supports("bmi") && __builtin_cpu_supports("bmi2") &&
      __builtin_cpu_supports("fma") && __builtin_cpu_supports("avx512f") &&
      __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512dq") &&
      __builtin_cpu_supports("avx512bw"))
    return Isa::kAvx512;
  if (avx2) return Isa::kAvx2;
#endif
  return Isa::kBaseline;
}

Isa UsedWalkIsa() {
  static const Isa cpu = CpuWalkIsa();
  return std::min(cpu, widest_allowed.load(std::memory_order_relaxed));
}

}  // namespace

bool WideBvh::Intersect(const Ray& ray, Hit* hit) const {
#if RAYSTACK_HAS_WALK_AVX2
  switch (UsedWalkIsa()) {
    case Isa::kAvx512: return walks_avx512::Intersect(*this, ray, hit);
    case Isa::kAvx2: return walks_avx2::Intersect(*this, ray, hit);
    case Isa::kBaseline: break;
  }
#endif
  return walks_baseline::Intersect(*this, ray, hit);
}

bool WideBvh::Occluded(const Ray& ray) const {
#if RAYSTACK_HAS_WALK_AVX2
  switch (UsedWalkIsa()) {
    case Isa::kAvx512: return walks_avx512::Occluded(*this, ray);
    case Isa::kAvx2: return walks_avx2::Occluded(*this, ray);
    case Isa::kBaseline: break;
  }
#endif
  return walks_baseline::Occluded(*this, ray);
}

uint32_t WideBvh::IntersectPacket(std::span<const Ray> rays, std::span<Hit> hits) const {
  CHECK(hits.size() >= rays.size() && rays.size() <= static_cast<size_t>(kPacketSize));
#if RAYSTACK_HAS_WALK_AVX2
  switch (UsedWalkIsa()) {
    case Isa::kAvx512: return walks_avx512::IntersectPackets(*this, rays, hits);
    case Isa::kAvx2: return walks_avx2::IntersectPackets(*this, rays, hits);
    case Isa::kBaseline: break;
  }
#endif
  return walks_baseline::IntersectPackets(*this, rays, hits);
}

uint32_t WideBvh::OccludedPacket(std::span<const Ray> rays) const {
  CHECK(rays.size() <= static_cast<size_t>(kPacketSize));
#if RAYSTACK_HAS_WALK_AVX2
  switch (UsedWalkIsa()) {
    case Isa::kAvx512: return walks_avx512::OccludedPackets(*this, rays);
    case Isa::kAvx2: return walks_avx2::OccludedPackets(*this, rays);
    case Isa::kBaseline: break;
  }
#endif
  return walks_baseline::OccludedPackets(*this, rays);
}

WideBvh::WalkIsa WideBvh::LimitWalks(WalkIsa widest) {
  widest_allowed.store(widest, std::memory_order_relaxed);
  return UsedWalkIsa();
}

const char* WideBvh::WalkIsaName(WalkIsa isa) {
  switch (isa) {
    case Isa::kAvx512: return "AVX2 with AVX-512";
    case Isa::kAvx2: return "AVX2";
    case Isa::kBaseline: break;
  }
  return "baseline";
}

}  // namespace raystack
