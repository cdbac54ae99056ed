#pragma once
// A ray that may wait: everything needed to resume it after any number of block loads (thesis
// TAB. VI.2), in 64 bytes. No pointers: a record is copied between queues, threads and (later)
// processes as plain bytes.

#include <cmath>
#include <cstdint>

#include "common/geometry/vec.h"

namespace raystack::slave {

enum class RayType : uint8_t { kPrimary = 0, kShadow, kSpecular, kDiffuse };
inline constexpr int kRayTypeCount = 4;

struct RayRecord {
  Vec3f origin;
  Vec3f direction;  // normalised for radiance rays; towards the light (length = distance) for shadow rays
  float tmax;       // closest hit so far (radiance) or the far end (shadow)
  uint32_t hit_id;  // source triangle id of the closest hit so far (kInvalidId: none)
  uint32_t slot;    // the sample this ray contributes to, in its thread's slot table
  Vec3f weight;     // path throughput (radiance rays) or the contribution if unoccluded (shadow)
  uint32_t normal;  // shading normal at the closest hit, octahedral, facing the ray's origin
  uint16_t material;  // material at the closest hit (16 bits of store::kNoMaterial = none)
  uint8_t type;       // RayType
  uint8_t depth;      // bounces so far
  uint16_t priority;  // the pixel's priority, inherited by every child
  uint8_t flags;      // kHitBackFace, kOccluded
  // Diffuse rays: the cosine at the surface they left, in 255ths (QuantizeCosine): the density
  // they were drawn with, which weighs an emitter they meet against next-event estimation's.
  uint8_t origin_cosine;
  // The hit triangle's own normal, octahedral, on the side `normal` faces: secondary rays start
  // off the surface along it (the hit point's error is measured against the surface's plane,
  // which a shading normal leaning from it does not see).
  uint32_t geometric_normal;
};
static_assert(sizeof(RayRecord) == 64, "a waiting ray costs 64 bytes; keep it so");

inline constexpr uint8_t kHitBackFace = 1;  // the closest hit is on the triangle's back side
inline constexpr uint8_t kOccluded = 2;     // a shadow ray found a blocker
inline constexpr uint8_t kPretraced = 4;    // bvh mode: its closest hit was found with its packet

inline RayType TypeOf(const RayRecord& r) { return static_cast<RayType>(r.type); }

// A cosine in [0, 1] to 255ths and back: both sides of multiple importance sampling take the
// density of a diffuse direction from the same 8 bits, so their weights still sum to one.
inline uint8_t QuantizeCosine(float c) {
  return static_cast<uint8_t>(std::lround(std::fmin(1.0f, std::fmax(0.0f, c)) * 255.0f));
}
inline float CosineOf(uint8_t q) { return static_cast<float>(q) * (1.0f / 255.0f); }
inline bool IsShadow(const RayRecord& r) { return TypeOf(r) == RayType::kShadow; }

// Octahedral unit-vector encoding in 2 x 16 bits (error < 1e-4 rad): the normal rides along
// with a waiting ray after its block may have been unloaded.
inline uint32_t EncodeNormal(Vec3f n) {
  const float l1 = std::fabs(n.x) + std::fabs(n.y) + std::fabs(n.z);
  if (!(l1 > 0)) return 0x80008000u;  // (0,0,1)-ish: only for degenerate input
  float u = n.x / l1, v = n.y / l1;
  if (n.z < 0) {
    const float ou = u, ov = v;
    u = (1 - std::fabs(ov)) * (ou >= 0 ? 1.0f : -1.0f);
    v = (1 - std::fabs(ou)) * (ov >= 0 ? 1.0f : -1.0f);
  }
  auto q = [](float x) {
    const float c = std::fmin(1.0f, std::fmax(-1.0f, x));
    return static_cast<uint32_t>(std::lround((c * 0.5f + 0.5f) * 65535.0f));
  };
  return q(u) | (q(v) << 16);
}

inline Vec3f DecodeNormal(uint32_t e) {
  const float u = static_cast<float>(e & 0xffffu) / 65535.0f * 2.0f - 1.0f;
  const float v = static_cast<float>(e >> 16) / 65535.0f * 2.0f - 1.0f;
  Vec3f n{u, v, 1.0f - std::fabs(u) - std::fabs(v)};
  if (n.z < 0) {
    const float ou = n.x, ov = n.y;
    n.x = (1 - std::fabs(ov)) * (ou >= 0 ? 1.0f : -1.0f);
    n.y = (1 - std::fabs(ou)) * (ov >= 0 ? 1.0f : -1.0f);
  }
  return Normalize(n);
}

}  // namespace raystack::slave
