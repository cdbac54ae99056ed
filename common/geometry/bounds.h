#pragma once
// Axis-aligned boxes. An empty box has lower > upper on every axis, so Extend() just works.

#include <limits>

#include "common/geometry/vec.h"

namespace raystack {

struct Bounds3f {
  Vec3f lower{std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
              std::numeric_limits<float>::infinity()};
  Vec3f upper{-std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
              -std::numeric_limits<float>::infinity()};

  bool Empty() const { return lower.x > upper.x || lower.y > upper.y || lower.z > upper.z; }
  Vec3f Extent() const { return upper - lower; }
  Vec3f Center() const { return (lower + upper) * 0.5f; }
  float HalfArea() const {
    if (Empty()) return 0;
    Vec3f e = Extent();
    return e.x * e.y + e.y * e.z + e.z * e.x;
  }
  int MaxAxis() const {
    Vec3f e = Extent();
    return e.x >= e.y && e.x >= e.z ? 0 : (e.y >= e.z ? 1 : 2);
  }
  void Extend(Vec3f p) {
    lower = Min(lower, p);
    upper = Max(upper, p);
  }
  void Extend(const Bounds3f& b) {
    lower = Min(lower, b.lower);
    upper = Max(upper, b.upper);
  }
  bool Contains(Vec3f p) const {
    return p.x >= lower.x && p.x <= upper.x && p.y >= lower.y && p.y <= upper.y &&
           p.z >= lower.z && p.z <= upper.z;
  }
  bool Contains(const Bounds3f& b) const { return Contains(b.lower) && Contains(b.upper); }
  bool Overlaps(const Bounds3f& b) const {
    return lower.x <= b.upper.x && upper.x >= b.lower.x && lower.y <= b.upper.y &&
           upper.y >= b.lower.y && lower.z <= b.upper.z && upper.z >= b.lower.z;
  }
};

inline Bounds3f Intersection(const Bounds3f& a, const Bounds3f& b) {
  return {Max(a.lower, b.lower), Min(a.upper, b.upper)};
}

}  // namespace raystack
