#include "tools/prep/clip.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/geometry/next_float.h"

namespace raystack::prep {
namespace {

struct P {
  double v[3];
};

// Keeps the part of polygon `in` (n points) on the side `sign * (x[axis] - plane) <= 0`.
int ClipPlane(const P* in, int n, int axis, double plane, double sign, P* out) {
  int m = 0;
  for (int i = 0; i < n; ++i) {
    const P& a = in[i];
    const P& b = in[(i + 1) % n];
    const double da = sign * (a.v[axis] - plane), db = sign * (b.v[axis] - plane);
    if (da <= 0) out[m++] = a;
    if ((da < 0 && db > 0) || (da > 0 && db < 0)) {
      const double s = da / (da - db);
      P c;
      for (int k = 0; k < 3; ++k) c.v[k] = a.v[k] + s * (b.v[k] - a.v[k]);
      c.v[axis] = plane;  // exactly on the plane, whatever the rounding of s
      out[m++] = c;
    }
  }
  return m;
}

}  // namespace

Bounds3f ClipTriangleToCell(const Vec3f p[3], const Bounds3f& cell) {
  Bounds3f tri;
  for (int i = 0; i < 3; ++i) tri.Extend(p[i]);
  if (cell.Contains(tri)) return tri;  // the common case: wholly inside
  // Widen the cell by a few ulps of its size so touching counts as overlapping.
  double lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    const double lower = cell.lower[a], upper = cell.upper[a];
    const double pad = 1e-6 * (upper - lower) + 1e-30 + 1e-7 * std::fabs(upper);
    lo[a] = lower - pad;
    hi[a] = upper + pad;
  }
  const Bounds3f widened{{static_cast<float>(lo[0]), static_cast<float>(lo[1]),
                          static_cast<float>(lo[2])},
                         {static_cast<float>(hi[0]), static_cast<float>(hi[1]),
                          static_cast<float>(hi[2])}};
  if (Intersection(tri, widened).Empty()) return Bounds3f{};

  // Up to 3 + 6 points after six planes.
  P a[9], b[9];
  for (int i = 0; i < 3; ++i) a[i] = {{p[i].x, p[i].y, p[i].z}};
  int n = 3;
  for (int axis = 0; axis < 3 && n > 0; ++axis) {
    n = ClipPlane(a, n, axis, hi[axis], 1.0, b);
    n = ClipPlane(b, n, axis, lo[axis], -1.0, a);
  }
  if (n == 0) return Bounds3f{};
  double mn[3], mx[3];
  for (int k = 0; k < 3; ++k) mn[k] = mx[k] = a[0].v[k];
  for (int i = 1; i < n; ++i)
    for (int k = 0; k < 3; ++k) {
      mn[k] = std::min(mn[k], a[i].v[k]);  // finite points: no NaN to care for, unlike fmin
      mx[k] = std::max(mx[k], a[i].v[k]);
    }
  Bounds3f out;
  for (int k = 0; k < 3; ++k) {
    // Round outward, then never beyond the triangle's own box (which is exact).
    float lo_f = NextDown(static_cast<float>(mn[k]));
    float hi_f = NextUp(static_cast<float>(mx[k]));
    // ... nor beyond the cell: blocks lie inside their cells. Points of the triangle within
    // the widening but outside the cell belong to the neighbour, which has the triangle too.
    out.lower[k] = std::max({lo_f, tri.lower[k], cell.lower[k]});
    out.upper[k] = std::min({hi_f, tri.upper[k], cell.upper[k]});
    if (out.lower[k] > out.upper[k]) return Bounds3f{};
  }
  return out;
}

}  // namespace raystack::prep
