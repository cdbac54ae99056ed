#include "common/geometry/offset_ray.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "common/geometry/ray.h"
#include "common/geometry/triangle.h"

namespace raystack {
namespace {

// Signed distance from q to the plane of (a, b, c), in double from the float vertices, on
// the side of `n`.
double SideOf(Vec3f q, Vec3f a, Vec3f b, Vec3f c, Vec3f n) {
  const double e1[3] = {double{b.x} - double{a.x}, double{b.y} - double{a.y},
                        double{b.z} - double{a.z}};
  const double e2[3] = {double{c.x} - double{a.x}, double{c.y} - double{a.y},
                        double{c.z} - double{a.z}};
  double g[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                 e1[0] * e2[1] - e1[1] * e2[0]};
  const double length = std::sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
  double side = g[0] * double{n.x} + g[1] * double{n.y} + g[2] * double{n.z} > 0 ? 1 : -1;
  return side * (g[0] * (double{q.x} - double{a.x}) + g[1] * (double{q.y} - double{a.y}) +
                 g[2] * (double{q.z} - double{a.z})) / length;
}

struct Scale {
  double size, offset, eye_radii;
};

// Random triangles of every size at every offset, hit from eyes near and far: the offset
// origin is strictly on the side of the normal it was pushed to, for both sides.
TEST(OffsetRayOrigin, LeavesTheSurfaceOnTheNormalsSideAtEveryScale) {
  std::mt19937 rng(3);
  std::normal_distribution<double> gauss;
  std::uniform_real_distribution<double> unit(0.05, 0.9);
  int checked = 0, wrong_side = 0;
  for (Scale s : {Scale{1e-4, 0, 3}, Scale{1e-4, 0, 1e4}, Scale{1, 0, 3}, Scale{1, 1e3, 1e4},
                  Scale{1e2, 1e6, 3}, Scale{1e5, 0, 1e4}, Scale{1e5, 1e6, 3}}) {
    for (int i = 0; i < 20000; ++i) {
      auto point = [&](double radius) {
        Vec3f p;
        for (int a = 0; a < 3; ++a) {
          p[a] = static_cast<float>(s.offset + gauss(rng) * radius * s.size);
        }
        return p;
      };
      const Vec3f a = point(1), b = point(1), c = point(1);
      const double w1 = unit(rng), w2 = unit(rng) * (1 - w1);
      Vec3f target;
      for (int k = 0; k < 3; ++k) {
        target[k] = static_cast<float>(double{a[k]} + w1 * (double{b[k]} - double{a[k]}) +
                                       w2 * (double{c[k]} - double{a[k]}));
      }
      const Vec3f eye = point(s.eye_radii);
      const Ray ray{eye, Normalize(target - eye)};
      float t, u, v;
      if (!IntersectTriangle(RayTriangleSetup(ray), a, b, c, 0, 1e30f, &t, &u, &v)) continue;
      const Vec3f ng = Normalize(Cross(b - a, c - a));
      if (!(std::fabs(Dot(ng, ray.direction)) > 0.05f)) continue;  // grazing: p is ill-defined
      const Vec3f p = ray.origin + ray.direction * t;
      const Vec3f error = HitPointError(ray.origin, ray.direction, t);
      for (Vec3f n : {ng, -ng}) {
        ++checked;
        wrong_side += !(SideOf(OffsetRayOrigin(p, n, error), a, b, c, n) > 0);
      }
    }
  }
  EXPECT_GT(checked, 200000);
  EXPECT_EQ(wrong_side, 0);
}

// The offset scales with the model: a model 1e-4 across at the origin, seen from 3e-4 away,
// gets an offset far below its size (Waechter and Binder's fixed 1/65536 near the origin was
// 15% of it); at 1e3 the offset stays under Waechter and Binder's 256 float steps.
TEST(OffsetRayOrigin, OffsetIsSmallAgainstTheModel) {
  const Vec3f n{0, 0, 1};
  for (double offset : {0.0, 1e3}) {
    const auto o = static_cast<float>(offset);
    const Vec3f eye{o, o, o + 3e-4f};
    const Vec3f p{o + 2e-5f, o - 1e-5f, o};
    const Vec3f dir = p - eye;
    const Vec3f moved = OffsetRayOrigin(p, n, HitPointError(eye, dir, 1.0f));
    const double distance = double{moved.z} - double{p.z};
    EXPECT_GT(distance, 0);
    const double step = offset == 0 ? 1e-4 * 1e-3 : 256 * 0x1p-14;  // float spacing at 1e3: 2^-14
    EXPECT_LT(distance, step) << "at " << offset;
  }
}

TEST(OffsetRayOrigin, MovesOnlyAlongTheNormalsAxes) {
  const Vec3f p{1, 2, 3};
  const Vec3f moved = OffsetRayOrigin(p, {0, 1, 0}, HitPointError({1, 5, 3}, {0, -1, 0}, 3));
  EXPECT_EQ(moved.x, p.x);
  EXPECT_EQ(moved.z, p.z);
  EXPECT_GT(moved.y, p.y);
}

}  // namespace
}  // namespace raystack
