#pragma once
// Watertight ray/triangle intersection (Woop, Benthin, Wald, "Watertight Ray/Triangle
// Intersection", JCGT 2013): the ray is sheared so it runs along +z through the origin, and the
// 2D edge functions are evaluated exactly enough (double fallback on a zero) that a ray aimed
// at a shared edge or vertex hits at least one of the triangles sharing it.
// The hot path is inline, branch-light and allocation-free.

#include <cmath>
#include <cstdint>

#include "common/geometry/ray.h"
#include "common/geometry/vec.h"

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace raystack {

// Per-ray constants, computed once per ray and reused for every triangle it meets. WideBvh's
// packets compute the same across their lanes (RayLanes, wide_bvh_packet_walk.inc): a change
// here must be made there too (the packet tests compare the two bit for bit).
struct RayTriangleSetup {
  Vec3f origin;
  Vec3f direction;
  int kx, ky, kz;    // axis permutation: kz is the ray's dominant axis
  float sx, sy, sz;  // shear

  RayTriangleSetup() = default;  // for arrays filled later (packets)
  explicit RayTriangleSetup(const Ray& ray) : origin(ray.origin), direction(ray.direction) {
    Vec3f d = ray.direction;
    float ax = std::fabs(d.x), ay = std::fabs(d.y), az = std::fabs(d.z);
    kz = ax > ay ? (ax > az ? 0 : 2) : (ay > az ? 1 : 2);
    kx = kz == 2 ? 0 : kz + 1;
    ky = kx == 2 ? 0 : kx + 1;
    if (d[kz] < 0) {  // keep the winding of the sheared triangle
      int tmp = kx;
      kx = ky;
      ky = tmp;
    }
    sx = d[kx] / d[kz];
    sy = d[ky] / d[kz];
    sz = 1.0f / d[kz];
  }
};

// IntersectTriangle's inside test on the edge values: false when they have mixed signs.
inline bool EdgesAccept(float u, float v, float w) {
  return !((u < 0 || v < 0 || w < 0) && (u > 0 || v > 0 || w > 0));
}

// A triangle's plane in double, for IntersectTriangle's distance: corner p0 and the normal
// (p1 - p0) x (p2 - p0). Shared by every ray tested against the triangle (packets).
struct TrianglePlane {
  double x0, y0, z0, nx, ny, nz;

  TrianglePlane(Vec3f p0, Vec3f p1, Vec3f p2) : x0(p0.x), y0(p0.y), z0(p0.z) {
    using D = double;
    const D e1x = D{p1.x} - x0, e1y = D{p1.y} - y0, e1z = D{p1.z} - z0;
    const D e2x = D{p2.x} - x0, e2y = D{p2.y} - y0, e2z = D{p2.z} - z0;
    nx = e1y * e2z - e1z * e2y;
    ny = e1z * e2x - e1x * e2z;
    nz = e1x * e2y - e1y * e2x;
  }
};

// IntersectTriangle once the ray is known to pass inside (EdgesAccept on its final edge values
// u, v, w): the distance, its range check, and the barycentrics.
//
// Distance from the plane equation in double. The sheared form (sum of weighted z over det)
// cancels badly when the hit is close relative to the triangle's size or distance from the
// origin (1-2% off on a wall of the conference room), which is enough for a box test to cull
// an equal or closer hit. In double the result is the correctly rounded distance to the exact
// plane, so every traversal order finds the same closest hit.
inline bool FinishTriangleHit(Vec3f origin, Vec3f direction, const TrianglePlane& plane, float u,
                              float v, float w, float tmin, float tmax, float* t_out,
                              float* u_out, float* v_out) {
  const float det = u + v + w;
  if (det == 0.0f) return false;
  using D = double;
  const D denominator =
      plane.nx * D{direction.x} + plane.ny * D{direction.y} + plane.nz * D{direction.z};
  if (denominator == 0.0) return false;
  const D numerator = plane.nx * (plane.x0 - D{origin.x}) + plane.ny * (plane.y0 - D{origin.y}) +
                      plane.nz * (plane.z0 - D{origin.z});
  const float t = static_cast<float>(numerator / denominator);
  if (!(t > tmin && t < tmax)) return false;  // also rejects NaN
  const float inv_det = 1.0f / det;
  *t_out = t;
  *u_out = v * inv_det;
  *v_out = w * inv_det;
  return true;
}

// Returns true and fills t (in (tmin, tmax)), u, v (barycentrics of p1, p2) on a hit. Both
// faces count (no culling). A triangle with coincident vertices never hits. One with distinct
// but collinear vertices can, on its segment: the float shear makes it a sliver of rounding
// width, so zero-area triangles are dropped when a model is converted.
inline bool IntersectTriangle(const RayTriangleSetup& s, Vec3f p0, Vec3f p1, Vec3f p2, float tmin,
                              float tmax, float* t_out, float* u_out, float* v_out) {
  const Vec3f a = p0 - s.origin, b = p1 - s.origin, c = p2 - s.origin;
  const float ax = a[s.kx] - s.sx * a[s.kz], ay = a[s.ky] - s.sy * a[s.kz];
  const float bx = b[s.kx] - s.sx * b[s.kz], by = b[s.ky] - s.sy * b[s.kz];
  const float cx = c[s.kx] - s.sx * c[s.kz], cy = c[s.ky] - s.sy * c[s.kz];

  float u = cx * by - cy * bx;
  float v = ax * cy - ay * cx;
  float w = bx * ay - by * ax;
  if (u == 0.0f || v == 0.0f || w == 0.0f) {  // on an edge in float: decide in double
    const double dax = ax, day = ay, dbx = bx, dby = by, dcx = cx, dcy = cy;
    u = static_cast<float>(dcx * dby - dcy * dbx);
    v = static_cast<float>(dax * dcy - day * dcx);
    w = static_cast<float>(dbx * day - dby * dax);
  }
  if (!EdgesAccept(u, v, w)) return false;
  return FinishTriangleHit(s.origin, s.direction, TrianglePlane(p0, p1, p2), u, v, w, tmin, tmax,
                           t_out, u_out, v_out);
}

#if defined(__SSE2__)
// IntersectTriangle's sign test for 4 triangles at once, from their corners c already moved to
// the ray's origin and sheared, x[c] and y[c] (lane k: triangle k), with the same float
// operations. Bit k set: IntersectTriangle rejects triangle k too. A zero edge value, which
// IntersectTriangle decides in double, is never rejected here.
inline uint32_t EdgeRejected4(const __m128 x[3], const __m128 y[3]) {
  const __m128 u = _mm_sub_ps(_mm_mul_ps(x[2], y[1]), _mm_mul_ps(y[2], x[1]));
  const __m128 v = _mm_sub_ps(_mm_mul_ps(x[0], y[2]), _mm_mul_ps(y[0], x[2]));
  const __m128 w = _mm_sub_ps(_mm_mul_ps(x[1], y[0]), _mm_mul_ps(y[1], x[0]));
  const __m128 zero = _mm_setzero_ps();
  const __m128 any_zero = _mm_or_ps(_mm_or_ps(_mm_cmpeq_ps(u, zero), _mm_cmpeq_ps(v, zero)),
                                    _mm_cmpeq_ps(w, zero));
  const __m128 any_neg = _mm_or_ps(_mm_or_ps(_mm_cmplt_ps(u, zero), _mm_cmplt_ps(v, zero)),
                                   _mm_cmplt_ps(w, zero));
  const __m128 any_pos = _mm_or_ps(_mm_or_ps(_mm_cmpgt_ps(u, zero), _mm_cmpgt_ps(v, zero)),
                                   _mm_cmpgt_ps(w, zero));
  const __m128 rejected = _mm_andnot_ps(any_zero, _mm_and_ps(any_neg, any_pos));
  return static_cast<uint32_t>(_mm_movemask_ps(rejected));
}
#endif

}  // namespace raystack
