#pragma once
// A ray and a hit record, the currency between the store, the tracer and tests.

#include <cstdint>
#include <limits>

#include "common/geometry/vec.h"

namespace raystack {

struct Ray {
  Vec3f origin;
  Vec3f direction;  // need not be normalised; t is in units of |direction|
  float tmin = 0;
  float tmax = std::numeric_limits<float>::infinity();
};

inline constexpr uint32_t kInvalidId = 0xffffffffu;

struct Hit {
  float t = std::numeric_limits<float>::infinity();
  float u = 0, v = 0;                // barycentrics of vertices 1 and 2
  uint32_t triangle_id = kInvalidId;  // source triangle id (order of the input model)
  uint32_t block_id = kInvalidId;     // block that produced the hit
  uint32_t local_triangle = kInvalidId;  // triangle index inside that block

  bool Valid() const { return triangle_id != kInvalidId; }
};

// The one closest-hit rule used everywhere, so every traversal order finds the same hit:
// smaller t wins; at equal t (coplanar duplicates) the smaller source triangle id wins.
inline bool CloserThan(float t, uint32_t triangle_id, const Hit& best) {
  return t < best.t || (t == best.t && triangle_id < best.triangle_id);
}

}  // namespace raystack
