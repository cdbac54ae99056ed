#include "tools/import/polygon_split.h"

#include <cmath>
#include <utility>

namespace raystack::import {
namespace {

// Twice the signed area of (a, b, c): > 0 when the path turns left (counter-clockwise) at b.
double Turn(double au, double av, double bu, double bv, double cu, double cv) {
  return (bu - au) * (cv - av) - (bv - av) * (cu - au);
}

}  // namespace

bool PolygonSplitter::Split(std::span<const Vec3f> corners, std::vector<Triangle>* triangles) {
  triangles->clear();
  const auto n = static_cast<uint32_t>(corners.size());
  if (n < 3) return true;
  const auto fan = [&] {
    for (uint32_t i = 1; i + 1 < n; ++i) triangles->push_back({0, i, i + 1});
  };
  if (n == 3) {
    fan();
    return true;
  }
  // Newell's normal, from the first corner (the face's coordinates may be far from the origin).
  const auto at = [&](uint32_t i, int axis) {
    return double{corners[i][axis]} - double{corners[0][axis]};
  };
  double normal[3] = {0, 0, 0};
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t j = i + 1 == n ? 0 : i + 1;
    for (int k = 0; k < 3; ++k) {
      const int a = (k + 1) % 3, b = (k + 2) % 3;
      normal[k] += (at(i, a) - at(j, a)) * (at(i, b) + at(j, b));
    }
  }
  int k = 0;
  for (int axis = 1; axis < 3; ++axis)
    if (std::fabs(normal[axis]) > std::fabs(normal[k])) k = axis;
  if (!(normal[k] != 0)) {  // no area (or not finite): nothing to clip
    fan();
    return true;
  }
  // The plane of the other two axes, taken in the order that makes the face counter-clockwise.
  int a = (k + 1) % 3, b = (k + 2) % 3;
  if (normal[k] < 0) std::swap(a, b);
  u_.resize(n);
  v_.resize(n);
  for (uint32_t i = 0; i < n; ++i) {
    u_[i] = at(i, a);
    v_[i] = at(i, b);
  }
  bool convex = true;
  for (uint32_t i = 0; i < n && convex; ++i) {
    const uint32_t p = i == 0 ? n - 1 : i - 1, q = i + 1 == n ? 0 : i + 1;
    convex = Turn(u_[p], v_[p], u_[i], v_[i], u_[q], v_[q]) >= 0;
  }
  if (convex) {
    fan();
    return true;
  }
  if (n > kMaxClippedCorners) {
    fan();
    return false;
  }
  next_.resize(n);
  prev_.resize(n);
  for (uint32_t i = 0; i < n; ++i) {
    next_[i] = i + 1 == n ? 0 : i + 1;
    prev_[i] = i == 0 ? n - 1 : i - 1;
  }
  uint32_t left = n, corner = 0, misses = 0;
  while (left > 3) {
    if (!IsEar(corner)) {
      corner = next_[corner];
      if (++misses > left) {  // no ear in a whole turn: the rest crosses itself
        Fan(corner, triangles);
        return true;
      }
      continue;
    }
    const uint32_t p = prev_[corner], q = next_[corner];
    triangles->push_back({p, corner, q});
    next_[p] = q;
    prev_[q] = p;
    --left;
    misses = 0;
    corner = q;
  }
  Fan(corner, triangles);
  return true;
}

void PolygonSplitter::Fan(uint32_t first, std::vector<Triangle>* triangles) const {
  for (uint32_t j = next_[first]; next_[j] != first; j = next_[j])
    triangles->push_back({first, j, next_[j]});
}

// A corner that turns left, and whose triangle with its two neighbours holds no other corner
// of the ring: clipping it leaves a face that still covers exactly the rest. Only corners that
// do not turn left can lie in such a triangle, so only they are looked at.
bool PolygonSplitter::IsEar(uint32_t corner) const {
  const uint32_t p = prev_[corner], q = next_[corner];
  const double pu = u_[p], pv = v_[p], cu = u_[corner], cv = v_[corner], qu = u_[q], qv = v_[q];
  if (!(Turn(pu, pv, cu, cv, qu, qv) > 0)) return false;
  for (uint32_t r = next_[q]; r != p; r = next_[r]) {
    const double ru = u_[r], rv = v_[r];
    if (Turn(u_[prev_[r]], v_[prev_[r]], ru, rv, u_[next_[r]], v_[next_[r]]) > 0) continue;
    // A corner repeated at one of the triangle's own (a face bridged to its hole) is no obstacle.
    if ((ru == pu && rv == pv) || (ru == cu && rv == cv) || (ru == qu && rv == qv)) continue;
    if (Turn(pu, pv, cu, cv, ru, rv) >= 0 && Turn(cu, cv, qu, qv, ru, rv) >= 0 &&
        Turn(qu, qv, pu, pv, ru, rv) >= 0)
      return false;
  }
  return true;
}

}  // namespace raystack::import
