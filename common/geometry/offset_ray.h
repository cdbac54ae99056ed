#pragma once
// Where a secondary ray starts: the hit point pushed off the surface along its normal by a
// bound on the error of the hit point (the approach of pbrt-v4's OffsetRayOrigin, with the
// ulp-relative term of Waechter and Binder, Ray Tracing Gems ch. 6).
//
// A fixed epsilon fails both ways: too small far from the origin (the new ray re-hits its own
// surface: acne), too large near it (it skips thin geometry). Waechter and Binder step a few
// hundred ulps of the point itself, with a fixed 1/65536 below |p| = 1/32; that still fails
// twice: a model 1e-4 across at the origin gets an offset of 15% of its size, and a hit point
// rebuilt as origin + t * direction from a camera 10^4 radii away is off by ulps of the
// *camera's* coordinates, far more than ulps of the point (tests/slave/shadow_origin_test.cpp
// measured up to half the shadow rays self-occluded). So the bound here has both terms: the
// rounding of the reconstruction, relative to |origin| + |t * direction|, and a margin
// relative to |p|. It has no constant in scene units, so it holds at every scale and offset.

#include <cmath>
#include <cstdint>

#include "common/geometry/next_float.h"
#include "common/geometry/vec.h"

namespace raystack {

// Per-axis bound on the error of p = origin + direction * t computed in float, where t is the
// correctly rounded distance to the surface (the triangle test computes it in double).
inline Vec3f HitPointError(Vec3f origin, Vec3f direction, float t);

// `p` moved off its surface to the side `n` faces (the side the new ray leaves towards), by
// at least the projection of `p_error` on n, and by at least one float step on every axis
// where n has a component: the new origin is strictly on n's side of the surface.
inline Vec3f OffsetRayOrigin(Vec3f p, Vec3f n, Vec3f p_error);

// ---------------------------------------------------------------------------------------------

namespace offset_ray_internal {

// Three roundings (t, the product, the sum) of at most 2^-24 each, with a factor 4 margin.
inline constexpr float kReconstruction = 0x1p-21f;
// 4 to 8 ulps of the point: its own rounding to float. Waechter and Binder step 256 ulps,
// which at 1e5 is 2 units off the surface: enough to change the shading of a model 10 across
// (the translation test saw 22% of its pixels move by over 1% with 128 ulps); the triangle
// test's distance is correctly rounded, so the rest of the error is the reconstruction's.
inline constexpr float kSurface = 0x1p-21f;

}  // namespace offset_ray_internal

inline Vec3f HitPointError(Vec3f origin, Vec3f direction, float t) {
  using namespace offset_ray_internal;
  Vec3f error;
  for (int a = 0; a < 3; ++a) {
    const float along = std::fabs(direction[a] * t);
    const float p = std::fabs(origin[a] + direction[a] * t);
    error[a] = (std::fabs(origin[a]) + along) * kReconstruction + p * kSurface;
  }
  return error;
}

inline Vec3f OffsetRayOrigin(Vec3f p, Vec3f n, Vec3f p_error) {
  const float d = std::fabs(n.x) * p_error.x + std::fabs(n.y) * p_error.y +
                  std::fabs(n.z) * p_error.z;
  Vec3f out;
  for (int a = 0; a < 3; ++a) {
    out[a] = p[a] + n[a] * d;
    // Rounding the sum may have undone a step smaller than half an ulp: step once more (an
    // overflow to infinity stays there).
    if (!std::isfinite(out[a])) continue;
    if (n[a] > 0) out[a] = NextUp(out[a]);
    if (n[a] < 0) out[a] = NextDown(out[a]);
  }
  return out;
}

}  // namespace raystack
