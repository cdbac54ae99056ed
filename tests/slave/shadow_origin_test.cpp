// Robust secondary-ray origins at extreme scales and offsets (issue 6): on a lit convex
// object (a cube, a latitude-longitude sphere), a shadow ray from a visible point towards a
// light in front of its face can only be blocked by the object itself, which lies behind the
// face. So every occluded shadow ray is a false one (self-intersection: "acne"). The rays
// are the ones the real shader spawns (Shader::Finish: hit point from the ray, octahedral
// normal, OffsetRayOrigin), traced against the mesh through the BVH.

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "common/render/material_table.h"
#include "common/render/scene.h"
#include "slave/ray_record.h"
#include "slave/shading.h"
#include "tests/geometry/mesh_bvh.h"
#include "tests/geometry/test_meshes.h"

namespace raystack::slave {
namespace {

using geometry_test::ClosedMesh;
using geometry_test::MeshBvh;
using geometry_test::Triangle;

// Latitude-longitude sphere: each quad joins two points of one ring to two of the next, an
// isosceles trapezoid, so the faces are planar and the polyhedron convex (up to the float
// rounding of its vertices, a few ulps).
ClosedMesh UvSphere(int rings, int segments, double scale, double translate) {
  ClosedMesh mesh;
  mesh.scale = scale;
  const auto c = static_cast<float>(translate);
  mesh.center = {c, c, c};
  auto point = [&](int ring, int segment) {
    const double theta = std::numbers::pi * ring / rings;
    const double phi = 2 * std::numbers::pi * (segment % segments) / segments;
    const double q[3] = {std::sin(theta) * std::cos(phi), std::cos(theta),
                         std::sin(theta) * std::sin(phi)};
    Vec3f p;
    for (int a = 0; a < 3; ++a) p[a] = static_cast<float>(translate + scale * q[a]);
    return p;
  };
  for (int r = 0; r < rings; ++r) {
    for (int s = 0; s < segments; ++s) {
      const Vec3f a = point(r, s), b = point(r, s + 1), cc = point(r + 1, s + 1),
                  d = point(r + 1, s);
      if (r > 0) mesh.triangles.push_back({{a, b, d}});
      if (r < rings - 1) mesh.triangles.push_back({{b, cc, d}});
    }
  }
  return mesh;
}

struct OcclusionCount {
  int shadow_rays = 0;
  int falsely_occluded = 0;
  std::string first;
};

// Shoots primary rays from a camera `camera_radii` radii from the centre at random points of
// the object, shades each hit with one light in front of the hit face, and traces the
// shadow ray the shader spawned.
// `lean_deg`: the shading normal leans that far from the face's own, towards a random
// direction (as vertex normals interpolated across a coarse mesh do).
OcclusionCount LightTheObject(const ClosedMesh& mesh, double camera_radii, int primaries,
                              uint32_t seed, double lean_deg = 0) {
  const MeshBvh bvh(mesh.triangles);
  render::Scene scene;
  scene.lights.push_back({{0, 0, 0}, {1, 1, 1}});
  const render::MaterialTable materials;
  std::mt19937 rng(seed);
  std::normal_distribution<double> gauss;
  auto random_direction = [&] {
    double v[3], l2 = 0;
    for (double& x : v) {
      x = gauss(rng);
      l2 += x * x;
    }
    for (double& x : v) x /= std::sqrt(l2);
    return std::vector<double>(v, v + 3);
  };
  auto at = [&](const std::vector<double>& dir, double radii) {
    Vec3f p;
    for (int a = 0; a < 3; ++a) {
      p[a] = static_cast<float>(double{mesh.center[a]} + dir[a] * radii * mesh.scale);
    }
    return p;
  };
  OcclusionCount count;
  ShadeOutput out;
  for (int i = 0; i < primaries; ++i) {
    const Vec3f eye = at(random_direction(), camera_radii);
    const Vec3f aim = at(random_direction(), 0.5);
    Ray primary{eye, Normalize(aim - eye)};
    const Hit hit = bvh.Closest(primary);
    if (!hit.Valid()) continue;
    const Triangle& tri = mesh.triangles[hit.triangle_id];
    const Vec3f ng = Normalize(Cross(tri.p[1] - tri.p[0], tri.p[2] - tri.p[0]));
    const Vec3f facing = Dot(ng, primary.direction) > 0 ? -ng : ng;

    // A light 4 radii away, in front of the face (well above its plane: the face's outward
    // side is the side the camera saw it from).
    const Vec3f hit_point = primary.origin + primary.direction * hit.t;
    std::vector<double> to_light;
    do {
      to_light = random_direction();
    } while (to_light[0] * double{facing.x} + to_light[1] * double{facing.y} +
                 to_light[2] * double{facing.z} <
             0.2);
    Vec3f light;
    for (int a = 0; a < 3; ++a) {
      light[a] = static_cast<float>(double{hit_point[a]} + to_light[a] * 4 * mesh.scale);
    }
    scene.lights[0].position = light;
    const Shader shader(scene, materials);

    RayRecord record{};
    record.origin = primary.origin;
    record.direction = primary.direction;
    record.tmax = hit.t;
    record.hit_id = hit.triangle_id;
    record.weight = {1, 1, 1};
    record.geometric_normal = EncodeNormal(facing);
    Vec3f shading = facing;
    if (lean_deg > 0) {
      const std::vector<double> r = random_direction();
      const Vec3f towards{static_cast<float>(r[0]), static_cast<float>(r[1]),
                          static_cast<float>(r[2])};
      const Vec3f along = Normalize(towards - facing * Dot(towards, facing));
      const auto lean = static_cast<float>(lean_deg * std::numbers::pi / 180);
      shading = Normalize(facing * std::cos(lean) + along * std::sin(lean));
    }
    record.normal = EncodeNormal(shading);
    record.material = store::kNoMaterial16;
    record.type = static_cast<uint8_t>(RayType::kPrimary);
    shader.Finish(record, 0, 0, &out);
    for (const RayRecord& child : out.children) {
      if (TypeOf(child) != RayType::kShadow) continue;
      ++count.shadow_rays;
      Ray shadow{child.origin, child.direction};
      shadow.tmax = child.tmax;
      const uint32_t blocker = bvh.AnyHit(shadow);
      if (blocker == kInvalidId) continue;
      if (count.falsely_occluded++ == 0) {
        count.first = "from triangle " + std::to_string(hit.triangle_id) + " blocked by " +
                      std::to_string(blocker) + " at t = " + std::to_string(hit.t);
      }
    }
  }
  return count;
}

struct OriginCase {
  bool cube;
  double scale;
  double translate;
  double camera_radii;
};

class ShadowOrigin : public ::testing::TestWithParam<OriginCase> {};

TEST_P(ShadowOrigin, NoShadowRayIsFalselyOccludedOnAConvexObject) {
  const OriginCase c = GetParam();
  const ClosedMesh mesh = c.cube ? geometry_test::MakeClosedMesh(geometry_test::MeshShape::kCube,
                                                                 10, c.scale, c.translate)
                                 : UvSphere(24, 48, c.scale, c.translate);
  const OcclusionCount count = LightTheObject(mesh, c.camera_radii, 10000, 5);
  EXPECT_GT(count.shadow_rays, 5000);
  EXPECT_EQ(count.falsely_occluded, 0) << "of " << count.shadow_rays << "; first " << count.first;
}

// A shading normal leaning 70 degrees from the face: new rays still start on the face's side
// (they are offset along the face's own normal; offset along the shading normal, the origin
// stayed on the surface for some rays and the face shadowed itself).
TEST(ShadowOriginLeaning, NoShadowRayIsFalselyOccludedWithALeaningShadingNormal) {
  for (const OriginCase c : {OriginCase{false, 1.0, 1e3, 100}, OriginCase{false, 1.0, 0, 1e4},
                             OriginCase{true, 1e2, 1e6, 3}, OriginCase{true, 1e-2, 0, 100}}) {
    SCOPED_TRACE(std::string(c.cube ? "cube" : "sphere") + " at " + std::to_string(c.translate) +
                 ", camera " + std::to_string(c.camera_radii) + " radii");
    const ClosedMesh mesh = c.cube ? geometry_test::MakeClosedMesh(geometry_test::MeshShape::kCube,
                                                                   10, c.scale, c.translate)
                                   : UvSphere(24, 48, c.scale, c.translate);
    const OcclusionCount count = LightTheObject(mesh, c.camera_radii, 20000, 9, 70);
    EXPECT_GT(count.shadow_rays, 4000);
    EXPECT_EQ(count.falsely_occluded, 0) << "of " << count.shadow_rays << "; first " << count.first;
  }
}

std::string Sci(double x) {
  if (x == 0) return "0";
  const int e = static_cast<int>(std::lround(std::log10(x)));
  return e < 0 ? "1em" + std::to_string(-e) : "1e" + std::to_string(e);
}

std::vector<OriginCase> Cases() {
  std::vector<OriginCase> cases;
  for (bool cube : {true, false}) {
    for (double translate : {0.0, 1e3, 1e6}) {
      for (double scale : {1e-4, 1e-2, 1.0, 1e2, 1e5}) {
        // As in the watertight test: skip objects float cannot represent at that offset.
        const double spacing = translate == 0 ? 0 : std::ldexp(1.0, std::ilogb(translate) - 23);
        if (scale < 64 * spacing) continue;
        for (double camera : {3.0, 100.0, 1e4}) cases.push_back({cube, scale, translate, camera});
      }
    }
  }
  return cases;
}

INSTANTIATE_TEST_SUITE_P(Objects, ShadowOrigin, ::testing::ValuesIn(Cases()),
                         [](const ::testing::TestParamInfo<OriginCase>& param_info) {
                           const OriginCase& c = param_info.param;
                           return std::string(c.cube ? "Cube" : "Sphere") + "Scale" +
                                  Sci(c.scale) + "At" + Sci(c.translate) + "Camera" +
                                  std::to_string(static_cast<int>(c.camera_radii)) + "Radii";
                         });

}  // namespace
}  // namespace raystack::slave
