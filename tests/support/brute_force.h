#pragma once
// The reference the store is checked against: every source triangle tested in source order,
// with a conservative box per run of 64 consecutive triangles to skip most of them. No tree,
// no clipping, nothing shared with the store's build: only the triangle test and tie rule.

#include <algorithm>
#include <cstdint>
#include <vector>

#include "common/geometry/bounds.h"
#include "common/geometry/bvh.h"
#include "common/geometry/ray.h"
#include "common/geometry/triangle.h"

namespace raystack::testing {

struct Tri {
  Vec3f p[3];
};

class BruteForce {
 public:
  explicit BruteForce(std::vector<Tri> tris) : tris_(std::move(tris)) {
    for (size_t i = 0; i < tris_.size(); i += kRun) {
      Bounds3f b;
      for (size_t j = i; j < std::min(tris_.size(), i + kRun); ++j)
        for (const Vec3f& p : tris_[j].p) b.Extend(p);
      runs_.push_back(b);
    }
  }

  // Closest hit; triangle_id is the index in the source order.
  Hit Intersect(const Ray& ray) const {
    Hit best;
    best.t = ray.tmax;
    const RayTriangleSetup setup(ray);
    const RayBoxSetup box(ray);
    for (size_t r = 0; r < runs_.size(); ++r) {
      const float lo[3] = {runs_[r].lower.x, runs_[r].lower.y, runs_[r].lower.z};
      const float hi[3] = {runs_[r].upper.x, runs_[r].upper.y, runs_[r].upper.z};
      float t_enter;
      const float limit = std::nextafter(best.t, std::numeric_limits<float>::infinity());
      if (!IntersectBox(box, lo, hi, ray.tmin, limit, &t_enter)) continue;
      const size_t end = std::min(tris_.size(), (r + 1) * kRun);
      for (size_t i = r * kRun; i < end; ++i) {
        float t, u, v;
        const float tmax = std::nextafter(best.t, std::numeric_limits<float>::infinity());
        if (IntersectTriangle(setup, tris_[i].p[0], tris_[i].p[1], tris_[i].p[2], ray.tmin, tmax,
                              &t, &u, &v) &&
            CloserThan(t, static_cast<uint32_t>(i), best)) {
          best.t = t;
          best.u = u;
          best.v = v;
          best.triangle_id = static_cast<uint32_t>(i);
        }
      }
    }
    if (!best.Valid()) best.t = std::numeric_limits<float>::infinity();
    return best;
  }

  const std::vector<Tri>& triangles() const { return tris_; }

 private:
  static constexpr size_t kRun = 64;
  std::vector<Tri> tris_;
  std::vector<Bounds3f> runs_;
};

}  // namespace raystack::testing
