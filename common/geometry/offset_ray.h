#pragma once
// Where a secondary ray starts: the hit point pushed off the surface along its normal by an
// amount that scales with the point's magnitude (Waechter and Binder, Ray Tracing Gems ch. 6).
// A fixed epsilon fails both ways: too small far from the origin (the new ray re-hits its own
// surface: acne), too large near it (it skips thin geometry). Stepping in units of the float
// spacing at the point works at every scale and offset.

#include <bit>
#include <cmath>
#include <cstdint>

#include "common/geometry/vec.h"

namespace raystack {

// `n` is the side to leave towards (the normal facing where the new ray goes).
inline Vec3f OffsetRayOrigin(Vec3f p, Vec3f n) {
  constexpr float kOrigin = 1.0f / 32.0f;       // below this |p| use a fixed float offset
  constexpr float kFloatScale = 1.0f / 65536.0f;
  constexpr float kIntScale = 256.0f;           // ulps to step
  Vec3f out;
  for (int a = 0; a < 3; ++a) {
    const int32_t step = static_cast<int32_t>(kIntScale * n[a]);
    const int32_t bits = std::bit_cast<int32_t>(p[a]);
    const float stepped = std::bit_cast<float>(bits + (p[a] < 0 ? -step : step));
    out[a] = std::fabs(p[a]) < kOrigin ? p[a] + kFloatScale * n[a] : stepped;
  }
  return out;
}

}  // namespace raystack
