#pragma once
// Where a secondary ray starts: the hit point pushed off the surface along its normal by a
// bound on the error of the hit point (the approach of pbrt-v4's OffsetRayOrigin, with the
// ulp-relative term of Waechter and Binder, Ray Tracing Gems ch. 6).
//
// A fixed epsilon fails both ways: too small far from the origin (the new ray re-hits its own
// surface: acne), too large near it (it skips thin geometry). Waechter and Binder step a few
// hundred ulps of the point itself, with a fixed 1/65536 below |p| = 1/32; that still fails
// twice: a model 1e-4 across at the origin gets an offset of 15% of its size, and a hit point
// rebuilt as origin + t * direction in float from a camera 10^4 radii away is off by ulps of
// the *camera's* coordinates, far more than ulps of the point. A bound with that term (as this
// file had) is safe but pushes the origin that far: from a camera 5e6 away, 2.4 units, past
// a light near the surface. So the hit keeps more than its float distance: the rest of the
// double distance to the triangle's plane and a power of two bounding that distance's error
// (PreciseHitDistance, computed where the triangle is at hand; 5 bytes in a waiting ray), and
// the point is rebuilt in double. Its error is then ulps of the point itself, plus the plane
// distance's error (ulps of the triangle's corners and the ray's origin in double): no
// constant in scene units, no camera term at float precision, at every scale and offset.

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>

#include "common/geometry/next_float.h"
#include "common/geometry/triangle.h"
#include "common/geometry/vec.h"

namespace raystack {

// A hit's distance beyond its float t: the true distance to the plane of its triangle, as
// computed in double, is t + rest within 2^error_log2.
struct PreciseDistance {
  float rest = 0;
  int8_t error_log2 = 127;  // unknown: the largest bound
};

// For a hit at float distance `t` on triangle (p0, p1, p2) (IntersectTriangle's t).
inline PreciseDistance PreciseHitDistance(Vec3f origin, Vec3f direction, float t, Vec3f p0,
                                          Vec3f p1, Vec3f p2);

// The hit point rebuilt in double from the ray and its distance, rounded to float, and a
// per-axis bound on its error (`*error`).
inline Vec3f PreciseHitPoint(Vec3f origin, Vec3f direction, float t, PreciseDistance distance,
                             Vec3f* error);

// `p` moved off its surface to the side `n` faces (the side the new ray leaves towards), by
// at least the projection of `p_error` on n, and by at least one float step on every axis
// where n has a component: the new origin is strictly on n's side of the surface.
inline Vec3f OffsetRayOrigin(Vec3f p, Vec3f n, Vec3f p_error);

// ---------------------------------------------------------------------------------------------

namespace offset_ray_internal {

// The double evaluations (the plane distance's numerator and denominator, the point's
// product and sum): a few roundings of 2^-53 each on the sums of the terms' magnitudes, with
// a wide margin; it also covers the next ray's own test against the plane, which rounds as
// much, and the float rounding of `rest` (2^-24 of at most half an ulp of t).
inline constexpr double kDoubleEvaluation = 0x1p-46;
// 4 to 8 ulps of the point: its own rounding to float. Waechter and Binder step 256 ulps,
// which at 1e5 is 2 units off the surface: enough to change the shading of a model 10 across
// (the translation test saw 22% of its pixels move by over 1% with 128 ulps); the triangle
// test's distance is correctly rounded, so the rest of the error is the reconstruction's.
inline constexpr float kSurface = 0x1p-21f;

}  // namespace offset_ray_internal

inline PreciseDistance PreciseHitDistance(Vec3f origin, Vec3f direction, float t, Vec3f p0,
                                          Vec3f p1, Vec3f p2) {
  using namespace offset_ray_internal;
  const TrianglePlane plane(p0, p1, p2);
  double numerator, denominator;
  PlaneDistanceTerms(origin, direction, plane, &numerator, &denominator);
  PreciseDistance d;
  if (!(denominator != 0)) return d;
  const double exact = numerator / denominator;
  const double n[3] = {plane.nx, plane.ny, plane.nz}, x0[3] = {plane.x0, plane.y0, plane.z0};
  double numerator_terms = 0, denominator_terms = 0;
  for (int a = 0; a < 3; ++a) {
    numerator_terms += std::fabs(n[a]) * (std::fabs(x0[a]) + std::fabs(double{origin[a]}));
    denominator_terms += std::fabs(n[a] * double{direction[a]});
  }
  const double error = kDoubleEvaluation *
                       (numerator_terms + std::fabs(exact) * denominator_terms) /
                       std::fabs(denominator);
  if (!std::isfinite(exact) || !std::isfinite(error)) return d;
  d.rest = static_cast<float>(exact - double{t});
  // A power of two above the error (its exponent bits, plus one: no libm call on this path),
  // within int8_t: 2^-127 is far below any point's own rounding (zero and subnormal errors
  // land there), and 2^127 means no better than unknown.
  const int e = static_cast<int>(std::bit_cast<uint64_t>(error) >> 52 & 0x7ff) - 1023 + 1;
  d.error_log2 = static_cast<int8_t>(std::clamp(e, -127, 127));
  return d;
}

inline Vec3f PreciseHitPoint(Vec3f origin, Vec3f direction, float t, PreciseDistance distance,
                             Vec3f* error) {
  using namespace offset_ray_internal;
  const double along = double{t} + double{distance.rest};
  const double distance_error =  // 2^error_log2, a normal double
      std::bit_cast<double>(static_cast<uint64_t>(distance.error_log2 + 1023) << 52);
  Vec3f p;
  for (int a = 0; a < 3; ++a) {
    const double o = origin[a], d = direction[a];
    const double exact = o + d * along;
    p[a] = static_cast<float>(exact);
    // The distance's error along the ray, the double evaluation of the point, and its
    // rounding to float (with the margin of kSurface).
    const double e = std::fabs(d) * distance_error +
                     (std::fabs(o) + std::fabs(d * along)) * kDoubleEvaluation +
                     std::fabs(exact) * double{kSurface};
    (*error)[a] = static_cast<float>(std::min(e, 3.0e38));
  }
  return p;
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
