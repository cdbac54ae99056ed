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
  const auto fan = [&] {
    for (uint32_t i = 1; i + 1 < n; ++i) triangles->push_back({0, i, i + 1});
  };
  if (n <= 3 || !Project(corners)) {  // a triangle, or nothing to clip
    fan();
    return true;
  }
  const auto m = static_cast<uint32_t>(ring_.size());
  const bool convex = ProjectedIsConvex();
  if (convex && m == n) {  // what scanners write: the fan it always was
    fan();
    return true;
  }
  if (!convex && m > kMaxClippedCorners) {
    fan();
    return false;
  }
  next_.resize(m);
  prev_.resize(m);
  for (uint32_t i = 0; i < m; ++i) {
    next_[i] = i + 1 == m ? 0 : i + 1;
    prev_[i] = i == 0 ? m - 1 : i - 1;
  }
  ClipEars(convex, triangles);
  return true;
}

// The ring of corners, each run of equal ones once, and their projection on the plane of two
// axes, that of the axis Newell's normal is closest to left out. False when fewer than three
// distinct corners remain or the face has no area (or is not finite).
bool PolygonSplitter::Project(std::span<const Vec3f> corners) {
  // A corner written twice in a row turns by 0 at both copies, which would hide a notch from
  // the convexity test (their triangles would have no area anyway).
  ring_.clear();
  for (uint32_t i = 0; i < corners.size(); ++i)
    if (ring_.empty() || !(corners[i] == corners[ring_.back()])) ring_.push_back(i);
  while (ring_.size() > 1 && corners[ring_.back()] == corners[ring_.front()]) ring_.pop_back();
  const auto m = static_cast<uint32_t>(ring_.size());
  if (m < 3) return false;
  // From the first corner: the face's coordinates may be far from the origin.
  const auto at = [&](uint32_t i, int axis) {
    return double{corners[ring_[i]][axis]} - double{corners[ring_[0]][axis]};
  };
  double normal[3] = {0, 0, 0};
  for (uint32_t i = 0; i < m; ++i) {
    const uint32_t j = i + 1 == m ? 0 : i + 1;
    for (int k = 0; k < 3; ++k) {
      const int a = (k + 1) % 3, b = (k + 2) % 3;
      normal[k] += (at(i, a) - at(j, a)) * (at(i, b) + at(j, b));
    }
  }
  int k = 0;
  for (int axis = 1; axis < 3; ++axis)
    if (std::fabs(normal[axis]) > std::fabs(normal[k])) k = axis;
  if (!(normal[k] != 0)) return false;
  // The other two axes, in the order that makes the face counter-clockwise.
  int a = (k + 1) % 3, b = (k + 2) % 3;
  if (normal[k] < 0) std::swap(a, b);
  u_.resize(m);
  v_.resize(m);
  for (uint32_t i = 0; i < m; ++i) {
    u_[i] = at(i, a);
    v_[i] = at(i, b);
  }
  return true;
}

bool PolygonSplitter::ProjectedIsConvex() const {
  const auto m = static_cast<uint32_t>(ring_.size());
  for (uint32_t i = 0; i < m; ++i) {
    const uint32_t p = i == 0 ? m - 1 : i - 1, q = i + 1 == m ? 0 : i + 1;
    if (Turn(u_[p], v_[p], u_[i], v_[i], u_[q], v_[q]) < 0) return false;
  }
  return true;
}

// Ear clipping with a list of ears (Eberly): clipping a corner changes whether its two
// neighbours are ears and no other corner's, so each clip re-tests two corners, and the whole
// split takes time quadratic in the corners, not cubic. A convex ring is a fan.
void PolygonSplitter::ClipEars(bool convex, std::vector<Triangle>* triangles) {
  const auto emit = [&](uint32_t x, uint32_t y, uint32_t z) {
    triangles->push_back({ring_[x], ring_[y], ring_[z]});
  };
  const auto m = static_cast<uint32_t>(ring_.size());
  uint32_t left = m, last = 0;
  if (!convex) {
    removed_.assign(m, 0);
    ears_.clear();
    for (uint32_t i = 0; i < m; ++i)
      if (IsEar(i)) ears_.push_back(i);
    bool rescanned = false;
    while (left > 3) {
      if (ears_.empty()) {
        // No ear left: the rest crosses itself (or rounding hid one from the update): look at
        // every corner once more, then fan what is left.
        if (rescanned) break;
        rescanned = true;
        for (uint32_t i = next_[last], j = 0; j < left; i = next_[i], ++j)
          if (IsEar(i)) ears_.push_back(i);
        continue;
      }
      const uint32_t corner = ears_.back();
      ears_.pop_back();
      if (removed_[corner] || !IsEar(corner)) continue;  // listed before a neighbour was clipped
      const uint32_t p = prev_[corner], q = next_[corner];
      emit(p, corner, q);
      next_[p] = q;
      prev_[q] = p;
      removed_[corner] = 1;
      --left;
      last = p;
      rescanned = false;
      if (left > 3) {
        if (IsEar(p)) ears_.push_back(p);
        if (IsEar(q)) ears_.push_back(q);
      }
    }
  }
  for (uint32_t j = next_[last]; next_[j] != last; j = next_[j]) emit(last, j, next_[j]);
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
