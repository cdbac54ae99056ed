#pragma once
// A closed test mesh behind the in-block BVH, traced the way a block is (TraverseBvh + the
// watertight triangle test), without a store: the extreme-scale tests shoot 10^6 rays, so the
// loop must be direct.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "common/geometry/bvh.h"
#include "common/geometry/ray.h"
#include "common/geometry/triangle.h"
#include "tests/geometry/test_meshes.h"

namespace raystack::geometry_test {

class MeshBvh {
 public:
  // `skipped` (optional): a triangle left out of every query, so a test can make a crack.
  explicit MeshBvh(const std::vector<Triangle>& triangles, uint32_t skipped = kInvalidId)
      : triangles_(triangles), skipped_(skipped) {
    std::vector<BvhBuildPrimitive> prims;
    for (const Triangle& t : triangles_) {
      Bounds3f b;
      for (const Vec3f& p : t.p) {
        b.Extend(p);
        magnitude_ = std::max({magnitude_, std::fabs(p.x), std::fabs(p.y), std::fabs(p.z)});
      }
      prims.push_back({b});
    }
    nodes_ = BuildBvh(prims, BvhBuildOptions{}, &order_);
  }

  // Closest hit in (ray.tmin, ray.tmax); triangle_id indexes `triangles`.
  Hit Closest(const Ray& ray) const {
    const RayTriangleSetup setup(ray);
    Hit best;
    best.t = ray.tmax;
    float tmax = ray.tmax;
    TraverseBvh(nodes_, ray, magnitude_, &tmax, [&](uint32_t first, uint32_t count) {
      for (uint32_t i = first; i < first + count; ++i) {
        const uint32_t id = order_[i];
        if (id == skipped_) continue;
        const Triangle& tri = triangles_[id];
        float t, u, v;
        if (IntersectTriangle(setup, tri.p[0], tri.p[1], tri.p[2], ray.tmin, ray.tmax, &t, &u,
                              &v) &&
            (t < best.t || !best.Valid())) {
          best.t = t, best.u = u, best.v = v, best.triangle_id = id;
          tmax = t;
        }
      }
      return false;
    });
    return best;
  }

  // Any hit in (ray.tmin, ray.tmax): the triangle's id, or kInvalidId.
  uint32_t AnyHit(const Ray& ray) const {
    const RayTriangleSetup setup(ray);
    uint32_t found = kInvalidId;
    float tmax = ray.tmax;
    TraverseBvh(nodes_, ray, magnitude_, &tmax, [&](uint32_t first, uint32_t count) {
      for (uint32_t i = first; i < first + count; ++i) {
        const uint32_t id = order_[i];
        if (id == skipped_) continue;
        const Triangle& tri = triangles_[id];
        float t, u, v;
        if (IntersectTriangle(setup, tri.p[0], tri.p[1], tri.p[2], ray.tmin, ray.tmax, &t, &u,
                              &v)) {
          found = id;
          return true;
        }
      }
      return false;
    });
    return found;
  }

  const std::vector<Triangle>& triangles() const { return triangles_; }

 private:
  std::vector<Triangle> triangles_;
  uint32_t skipped_;
  std::vector<BvhNode> nodes_;
  float magnitude_ = 0;  // the largest |coordinate|, for the box tests' margin
  std::vector<uint32_t> order_;
};

}  // namespace raystack::geometry_test
