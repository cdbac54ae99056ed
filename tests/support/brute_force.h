#pragma once
// The reference the store is checked against: every source triangle is a candidate, tested
// in runs of 64 (grouped by the Morton code of their centroids) behind one conservative box
// per run and one per 64 runs. The order of tests cannot change the answer: CloserThan is a total order on
// (t, id). No tree, no clipping, nothing shared with the store's build but the triangle test.

#include <algorithm>
#include <cmath>
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
    Bounds3f all;
    for (const Tri& t : tris_)
      for (const Vec3f& p : t.p) all.Extend(p);
    for (int a = 0; a < 3 && !tris_.empty(); ++a)  // the box tests' margin (a hit may lie just outside its box)
      magnitude_ = std::max({magnitude_, std::fabs(all.lower[a]), std::fabs(all.upper[a])});
    std::vector<std::pair<uint32_t, uint32_t>> keyed;  // (Morton code, index)
    for (uint32_t i = 0; i < tris_.size(); ++i) {
      const Vec3f c = (tris_[i].p[0] + tris_[i].p[1] + tris_[i].p[2]) * (1.0f / 3);
      uint32_t code = 0;
      for (int a = 0; a < 3; ++a) {
        const float e = all.upper[a] - all.lower[a];
        const float f = e > 0 ? (c[a] - all.lower[a]) / e : 0.0f;
        const uint32_t q = static_cast<uint32_t>(std::clamp(f, 0.0f, 1.0f) * 1023.0f);
        for (int bit = 0; bit < 10; ++bit) code |= ((q >> bit) & 1u) << (3 * bit + a);
      }
      keyed.push_back({code, i});
    }
    std::sort(keyed.begin(), keyed.end());
    for (const auto& k : keyed) order_.push_back(k.second);
    for (size_t i = 0; i < order_.size(); i += kRun) {
      Bounds3f b;
      for (size_t j = i; j < std::min(order_.size(), i + kRun); ++j)
        for (const Vec3f& p : tris_[order_[j]].p) b.Extend(p);
      runs_.push_back(b);
    }
    for (size_t i = 0; i < runs_.size(); i += kRun) {
      Bounds3f b;
      for (size_t j = i; j < std::min(runs_.size(), i + kRun); ++j) b.Extend(runs_[j]);
      groups_.push_back(b);
    }
  }

  // Closest hit; triangle_id is the index in the source order.
  Hit Intersect(const Ray& ray) const {
    Hit best;
    best.t = ray.tmax;
    const RayTriangleSetup setup(ray);
    const RayBoxSetup box(ray, magnitude_);
    auto may_hit = [&](const Bounds3f& b) {
      const float lo[3] = {b.lower.x, b.lower.y, b.lower.z};
      const float hi[3] = {b.upper.x, b.upper.y, b.upper.z};
      float t_enter;
      const float limit = std::nextafter(best.t, std::numeric_limits<float>::infinity());
      return IntersectBox(box, lo, hi, ray.tmin, limit, &t_enter);
    };
    for (size_t r = 0; r < runs_.size(); ++r) {
      if (r % kRun == 0 && !may_hit(groups_[r / kRun])) {
        r += kRun - 1;  // skip the whole group of runs
        continue;
      }
      if (!may_hit(runs_[r])) continue;
      const size_t end = std::min(tris_.size(), (r + 1) * kRun);
      for (size_t k = r * kRun; k < end; ++k) {
        const uint32_t i = order_[k];
        float t, u, v;
        const float tmax = std::nextafter(best.t, std::numeric_limits<float>::infinity());
        if (IntersectTriangle(setup, tris_[i].p[0], tris_[i].p[1], tris_[i].p[2], ray.tmin, tmax,
                              &t, &u, &v) &&
            CloserThan(t, i, best)) {
          best.t = t;
          best.u = u;
          best.v = v;
          best.triangle_id = i;
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
  float magnitude_ = 0;
  std::vector<uint32_t> order_;
  std::vector<Bounds3f> runs_;
  std::vector<Bounds3f> groups_;  // one box per 64 runs
};

}  // namespace raystack::testing
