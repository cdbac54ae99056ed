#include "common/geometry/triangle.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "tests/geometry/test_meshes.h"

namespace raystack {
namespace {

using geometry_test::ClosedMesh;
using geometry_test::MakeClosedMesh;
using geometry_test::MeshShape;
using geometry_test::Triangle;

constexpr float kInf = std::numeric_limits<float>::infinity();

struct TriangleHit {
  bool hit = false;
  float t = 0, u = 0, v = 0;
};

TriangleHit Intersect(const Ray& ray, Vec3f p0, Vec3f p1, Vec3f p2) {
  TriangleHit h;
  const RayTriangleSetup setup(ray);
  h.hit = IntersectTriangle(setup, p0, p1, p2, ray.tmin, ray.tmax, &h.t, &h.u, &h.v);
  return h;
}

const Vec3f kP0{0, 0, 1}, kP1{1, 0, 1}, kP2{0, 1, 1};

TEST(IntersectTriangle, HitsAlongZWithDistanceAndBarycentrics) {
  const Ray ray{{0.25f, 0.5f, 0}, {0, 0, 1}};
  const TriangleHit h = Intersect(ray, kP0, kP1, kP2);
  ASSERT_TRUE(h.hit);
  EXPECT_FLOAT_EQ(h.t, 1.0f);
  EXPECT_FLOAT_EQ(h.u, 0.25f);  // weight of p1 = (1, 0, 1)
  EXPECT_FLOAT_EQ(h.v, 0.5f);   // weight of p2 = (0, 1, 1)
}

TEST(IntersectTriangle, BarycentricsReconstructTheHitPoint) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> coord(-5, 5), weight(0.05f, 1);
  for (int i = 0; i < 1000; ++i) {
    const Vec3f p0{coord(rng), coord(rng), coord(rng)};
    const Vec3f p1{coord(rng), coord(rng), coord(rng)};
    const Vec3f p2{coord(rng), coord(rng), coord(rng)};
    float w0 = weight(rng), w1 = weight(rng), w2 = weight(rng);
    const float sum = w0 + w1 + w2;
    w0 /= sum, w1 /= sum, w2 /= sum;
    const Vec3f target = p0 * w0 + p1 * w1 + p2 * w2;
    const Vec3f origin{coord(rng) * 4, coord(rng) * 4, coord(rng) * 4};
    const Ray ray{origin, target - origin};
    const TriangleHit h = Intersect(ray, p0, p1, p2);
    if (Length(Cross(p1 - p0, p2 - p0)) < 1e-2f) continue;  // too thin for tight checks
    ASSERT_TRUE(h.hit) << i;
    EXPECT_NEAR(h.t, 1.0f, 1e-3f) << i;
    EXPECT_NEAR(h.u, w1, 1e-3f) << i;
    EXPECT_NEAR(h.v, w2, 1e-3f) << i;
  }
}

TEST(IntersectTriangle, BothWindingsHitWithTheSameDistance) {
  const Ray ray{{0.2f, 0.3f, -2}, {0, 0, 1}};
  const TriangleHit front = Intersect(ray, kP0, kP1, kP2);
  const TriangleHit back = Intersect(ray, kP0, kP2, kP1);
  ASSERT_TRUE(front.hit);
  ASSERT_TRUE(back.hit);
  EXPECT_EQ(front.t, back.t);
  EXPECT_FLOAT_EQ(front.u, back.v);  // swapping p1 and p2 swaps their weights
  EXPECT_FLOAT_EQ(front.v, back.u);
  // And from the other side, with a negative dominant direction.
  const Ray reverse{{0.2f, 0.3f, 4}, {0, 0, -1}};
  EXPECT_TRUE(Intersect(reverse, kP0, kP1, kP2).hit);
  EXPECT_TRUE(Intersect(reverse, kP0, kP2, kP1).hit);
}

TEST(IntersectTriangle, Misses) {
  // Beside the triangle, beyond the hypotenuse.
  EXPECT_FALSE(Intersect({{0.6f, 0.6f, 0}, {0, 0, 1}}, kP0, kP1, kP2).hit);
  EXPECT_FALSE(Intersect({{-0.1f, 0.5f, 0}, {0, 0, 1}}, kP0, kP1, kP2).hit);
  // Pointing away.
  EXPECT_FALSE(Intersect({{0.2f, 0.2f, 0}, {0, 0, -1}}, kP0, kP1, kP2).hit);
  // Parallel to the plane, both off it and inside it.
  EXPECT_FALSE(Intersect({{-1, 0.2f, 0}, {1, 0, 0}}, kP0, kP1, kP2).hit);
  EXPECT_FALSE(Intersect({{-1, 0.2f, 1}, {1, 0, 0}}, kP0, kP1, kP2).hit);
}

TEST(IntersectTriangle, HonoursTheOpenInterval) {
  Ray ray{{0.2f, 0.2f, 0}, {0, 0, 1}};
  ray.tmax = 1.0f;  // the hit is at exactly t = 1: excluded
  EXPECT_FALSE(Intersect(ray, kP0, kP1, kP2).hit);
  ray.tmax = 1.5f;
  EXPECT_TRUE(Intersect(ray, kP0, kP1, kP2).hit);
  ray.tmin = 1.0f;  // excluded at the lower end too
  EXPECT_FALSE(Intersect(ray, kP0, kP1, kP2).hit);
  ray.tmin = 0.5f;
  EXPECT_TRUE(Intersect(ray, kP0, kP1, kP2).hit);
}

TEST(IntersectTriangle, TrianglesWithCoincidentVerticesNeverHit) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> coord(-3, 3), unit(0, 1);
  for (int i = 0; i < 20000; ++i) {
    const Vec3f a{coord(rng), coord(rng), coord(rng)};
    const Vec3f b{coord(rng), coord(rng), coord(rng)};
    Triangle tri;
    switch (i % 4) {
      case 0: tri = {{a, a, a}}; break;
      case 1: tri = {{a, a, b}}; break;
      case 2: tri = {{a, b, a}}; break;
      default: tri = {{b, a, a}}; break;
    }
    // Aimed at the degenerate triangle, from anywhere or along its line.
    const Vec3f target = a + (b - a) * unit(rng);
    const Vec3f origin = i % 8 < 4 ? Vec3f{coord(rng), coord(rng), coord(rng)} * 3.0f
                                   : a + (a - b) * 2.0f;
    const Ray ray{origin, target - origin};
    EXPECT_FALSE(Intersect(ray, tri.p[0], tri.p[1], tri.p[2]).hit) << i;
  }
}

// Exactly collinear vertices are not exactly collinear any more once sheared in float, so the
// test can report a hit on such a sliver (a few percent of rays aimed at the line do). What
// it must not do is invent a distance: t is a convex combination of the vertices' depths
// along the ray's dominant axis. Dropping zero-area triangles is the converter's job.
TEST(IntersectTriangle, CollinearTrianglesHitOnlyWithinTheirDepthRange) {
  std::mt19937 rng(12);
  std::uniform_int_distribution<int> lattice(-20, 20), step(-2, 2);
  std::uniform_real_distribution<float> coord(-30, 30), unit(0, 1);
  int hits = 0;
  for (int i = 0; i < 100000; ++i) {
    const Vec3f a{float(lattice(rng)), float(lattice(rng)), float(lattice(rng))};
    const Vec3f d{float(step(rng)), float(step(rng)), float(step(rng))};
    if (d == Vec3f{}) continue;
    const Vec3f b = a + d, c = a + d * 2.0f;  // exact: small integers
    const Vec3f target = a + d * (unit(rng) * 3 - 0.5f);
    const Vec3f origin{coord(rng), coord(rng), coord(rng)};
    const Ray ray{origin, target - origin};
    const TriangleHit h = Intersect(ray, a, b, c);
    if (!h.hit) continue;
    ++hits;
    // Depth as the intersector measures it: along the dominant axis of the direction.
    const RayTriangleSetup setup(ray);
    const int kz = setup.kz;
    const float ta = (a[kz] - origin[kz]) / ray.direction[kz];
    const float tc = (c[kz] - origin[kz]) / ray.direction[kz];
    const float slack = 1e-4f * (std::fabs(ta) + std::fabs(tc));
    EXPECT_GE(h.t, std::min(ta, tc) - slack) << i;
    EXPECT_LE(h.t, std::max(ta, tc) + slack) << i;
  }
  EXPECT_LT(hits, 20000);
}

TEST(IntersectTriangle, AxisParallelRaysThroughVerticesAndEdgesHit) {
  // With an axis-aligned direction the shear is zero, so the test is exact: a ray through a
  // vertex or an edge point always hits.
  const Vec3f p0{0, 0, 2}, p1{4, 0, 2}, p2{0, 4, 2};
  for (Vec3f target : {p0, p1, p2, Vec3f{2, 0, 2}, Vec3f{2, 2, 2}, Vec3f{0, 2, 2}}) {
    for (float sign : {1.0f, -1.0f}) {
      const Ray ray{{target.x, target.y, 2 - 3 * sign}, {0, 0, sign}};
      EXPECT_TRUE(Intersect(ray, p0, p1, p2).hit) << target.x << " " << target.y;
    }
  }
}

// Shoots rays from outside a closed mesh to a point inside it, each passing (as closely as
// float allows) through a vertex, an edge midpoint or a triangle centroid. Every such segment
// crosses the surface, so a segment that meets no triangle found a crack.
struct LeakReport {
  int rays = 0;
  int leaks = 0;
  std::string first_leak;
};

bool SegmentHitsMesh(const ClosedMesh& mesh, const Ray& ray, size_t removed_triangle) {
  const RayTriangleSetup setup(ray);
  for (size_t i = 0; i < mesh.triangles.size(); ++i) {
    if (i == removed_triangle) continue;
    const Triangle& tri = mesh.triangles[i];
    float t, u, v;
    if (IntersectTriangle(setup, tri.p[0], tri.p[1], tri.p[2], ray.tmin, ray.tmax, &t, &u, &v)) {
      return true;
    }
  }
  return false;
}

// `removed_triangle` (if not SIZE_MAX) is left out of the mesh but not out of the targets.
LeakReport ShootThroughFeatures(const ClosedMesh& mesh, int rays_per_target, uint32_t seed,
                                size_t removed_triangle = SIZE_MAX) {
  std::vector<Vec3f> targets = mesh.vertices;
  for (const Triangle& tri : mesh.triangles) {
    for (int e = 0; e < 3; ++e) targets.push_back((tri.p[e] + tri.p[(e + 1) % 3]) * 0.5f);
    targets.push_back((tri.p[0] + tri.p[1] + tri.p[2]) * (1.0f / 3.0f));
  }
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> jitter(-0.3, 0.3), stretch(1.5, 4.0);
  const auto scale = static_cast<float>(mesh.scale);
  LeakReport report;
  auto shoot = [&](const Ray& ray, const Vec3f& target) {
    ++report.rays;
    if (SegmentHitsMesh(mesh, ray, removed_triangle)) return;
    if (report.leaks++ == 0) {
      report.first_leak = "target (" + std::to_string(target.x) + ", " +
                          std::to_string(target.y) + ", " + std::to_string(target.z) + ")";
    }
  };
  for (const Vec3f& target : targets) {
    for (int r = 0; r < rays_per_target; ++r) {
      // Inside point: the center moved by up to 0.3 of the inscribed radius per axis.
      Vec3f inside;
      for (int a = 0; a < 3; ++a) {
        inside[a] = static_cast<float>(double{mesh.center[a]} + mesh.scale * jitter(rng));
      }
      // Outside point on the line from `inside` through the target, so the segment from it to
      // `inside` runs through the target.
      const double k = stretch(rng);
      Vec3f outside;
      for (int a = 0; a < 3; ++a) {
        const double from = inside[a];
        outside[a] = static_cast<float>(from + (double{target[a]} - from) * k);
      }
      Ray ray{outside, inside - outside};
      ray.tmax = 1.0f;
      shoot(ray, target);
    }
    // Axis-parallel rays through the target along its dominant axis: zero shear, so they pass
    // through the vertex exactly. Only where the surface faces that axis, so they enter.
    const Vec3f offset = target - mesh.center;
    const int axis = std::fabs(offset.x) > std::fabs(offset.y)
                         ? (std::fabs(offset.x) > std::fabs(offset.z) ? 0 : 2)
                         : (std::fabs(offset.y) > std::fabs(offset.z) ? 1 : 2);
    if (std::fabs(offset[axis]) < 0.6f * Length(offset)) continue;
    const float sign = offset[axis] > 0 ? 1.0f : -1.0f;
    Ray ray{target, {}};
    ray.origin[axis] = target[axis] + sign * 2 * scale;
    ray.direction[axis] = -sign;
    ray.tmax = 2.5f * scale;  // ends inside, half a radius past the surface
    shoot(ray, target);
  }
  return report;
}

struct WatertightCase {
  const char* name;
  MeshShape shape;
  double scale;
  double translate;
};

class Watertight : public ::testing::TestWithParam<WatertightCase> {};

TEST_P(Watertight, RaysThroughSharedVerticesAndEdgesNeverLeak) {
  const WatertightCase c = GetParam();
  const ClosedMesh mesh = MakeClosedMesh(c.shape, 8, c.scale, c.translate);
  const LeakReport report = ShootThroughFeatures(mesh, 3, 1234);
  EXPECT_GT(report.rays, 10000);
  EXPECT_EQ(report.leaks, 0) << "of " << report.rays << " rays; first at " << report.first_leak;
}

constexpr MeshShape kCube = MeshShape::kCube;
constexpr MeshShape kSphere = MeshShape::kSphere;

INSTANTIATE_TEST_SUITE_P(
    Meshes, Watertight,
    ::testing::Values(WatertightCase{"Cube", kCube, 1, 0}, WatertightCase{"Sphere", kSphere, 1, 0},
                      WatertightCase{"CubeAt1e3", kCube, 1, 1e3},
                      WatertightCase{"SphereAt1e3", kSphere, 1, 1e3},
                      WatertightCase{"CubeAt1e6", kCube, 1, 1e6},
                      WatertightCase{"SphereAt1e6", kSphere, 1, 1e6},
                      WatertightCase{"CubeScaled1em4", kCube, 1e-4, 0},
                      WatertightCase{"SphereScaled1em4", kSphere, 1e-4, 0},
                      WatertightCase{"CubeScaled1e5", kCube, 1e5, 0},
                      WatertightCase{"SphereScaled1e5", kSphere, 1e5, 0}),
    [](const ::testing::TestParamInfo<WatertightCase>& param_info) {
      return std::string(param_info.param.name);
    });

// The harness must be able to see a crack: without one triangle, rays through its centroid
// leave the mesh unhit.
TEST(WatertightHarness, DetectsAMissingTriangle) {
  const ClosedMesh mesh = MakeClosedMesh(MeshShape::kCube, 8, 1, 0);
  const LeakReport report = ShootThroughFeatures(mesh, 3, 1234, 37);
  EXPECT_GT(report.leaks, 0);
}

}  // namespace
}  // namespace raystack
