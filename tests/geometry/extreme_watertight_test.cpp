// Watertightness at extreme scales and offsets (issue 6): rays aimed at the shared vertices,
// edge midpoints and centroids of closed meshes (a cube, a tessellated sphere, an irregular
// "scan"), translated by 0, 1e3 and 1e6 and scaled from 1e-4 to 1e5, traced through the BVH
// the way a block is. Every ray runs from outside the mesh to a point inside it, so one that
// meets no triangle went through a crack. About 10^6 rays in all.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "tests/geometry/mesh_bvh.h"
#include "tests/geometry/test_meshes.h"

namespace raystack::geometry_test {
namespace {

constexpr int kRaysPerCase = 100000;  // 11 cases per mesh: over 10^6 rays per mesh

struct LeakCount {
  int rays = 0;
  int leaks = 0;
  std::string first;
};

std::vector<Vec3f> Targets(const ClosedMesh& mesh) {
  std::vector<Vec3f> targets = mesh.vertices;
  for (const Triangle& tri : mesh.triangles) {
    for (int e = 0; e < 3; ++e) targets.push_back((tri.p[e] + tri.p[(e + 1) % 3]) * 0.5f);
    targets.push_back((tri.p[0] + tri.p[1] + tri.p[2]) * (1.0f / 3.0f));
  }
  return targets;
}

LeakCount Shoot(const ClosedMesh& mesh, const MeshBvh& bvh, int rays, uint32_t seed) {
  const std::vector<Vec3f> targets = Targets(mesh);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> jitter(-0.3, 0.3), stretch(1.5, 4.0);
  LeakCount count;
  auto shoot = [&](const Ray& ray, Vec3f target) {
    ++count.rays;
    if (bvh.Closest(ray).Valid()) return;
    if (count.leaks++ == 0) {
      count.first = "toward (" + std::to_string(target.x) + ", " + std::to_string(target.y) +
                    ", " + std::to_string(target.z) + ")";
    }
  };
  for (int r = 0; r < rays; ++r) {
    const Vec3f target = targets[static_cast<size_t>(r) % targets.size()];
    // Inside: the centre moved by up to 0.3 of the radius per axis (the scan's surface is at
    // least 0.7 from the centre). Outside: on the line from it through the target, at least
    // 4 radii away, beyond every mesh. The segment crosses the surface at the target.
    double inside[3], delta[3], length2 = 0;
    for (int a = 0; a < 3; ++a) {
      inside[a] = double{mesh.center[a]} + mesh.scale * jitter(rng);
      delta[a] = double{target[a]} - inside[a];
      length2 += delta[a] * delta[a];
    }
    const double k = std::max(stretch(rng), 4 * mesh.scale / std::sqrt(length2));
    Vec3f from, to;
    for (int a = 0; a < 3; ++a) {
      to[a] = static_cast<float>(inside[a]);
      from[a] = static_cast<float>(inside[a] + delta[a] * k);
    }
    Ray ray{from, to - from};
    ray.tmax = 1.0f;
    shoot(ray, target);
    // Every 16th target also gets an axis-parallel ray along its dominant axis: zero shear,
    // so the ray passes exactly through the vertex or edge point.
    if (r % 16 != 0 || r / 16 >= static_cast<int>(targets.size())) continue;
    const Vec3f offset = target - mesh.center;
    const int axis = std::fabs(offset.x) > std::fabs(offset.y)
                         ? (std::fabs(offset.x) > std::fabs(offset.z) ? 0 : 2)
                         : (std::fabs(offset.y) > std::fabs(offset.z) ? 1 : 2);
    // Nearly radial only: the ray then ends (level with the centre) less than 0.45 radii from
    // the centre, inside even the scan, whose surface dips to 0.75.
    if (std::fabs(offset[axis]) < 0.9f * Length(offset)) continue;
    const double sign = offset[axis] > 0 ? 1.0 : -1.0;
    Ray axial{target, {}};
    axial.origin[axis] = static_cast<float>(double{target[axis]} + sign * 3 * mesh.scale);
    axial.direction[axis] = static_cast<float>(-sign);
    axial.tmax = static_cast<float>(3 * mesh.scale + std::fabs(double{offset[axis]}));
    shoot(axial, target);
  }
  return count;
}

struct ExtremeCase {
  MeshShape shape;
  double scale;
  double translate;
};

std::string ShapeName(MeshShape s) {
  return s == MeshShape::kCube ? "Cube" : s == MeshShape::kSphere ? "Sphere" : "Scan";
}

std::string Sci(double x) {
  if (x == 0) return "0";
  const int e = static_cast<int>(std::lround(std::log10(x)));
  return e < 0 ? "1em" + std::to_string(-e) : "1e" + std::to_string(e);
}

class ExtremeWatertight : public ::testing::TestWithParam<ExtremeCase> {};

TEST_P(ExtremeWatertight, RaysAtSharedEdgesAndVerticesNeverLeak) {
  const ExtremeCase c = GetParam();
  const ClosedMesh mesh = MakeClosedMesh(c.shape, 10, c.scale, c.translate);
  const MeshBvh bvh(mesh.triangles);
  const LeakCount count = Shoot(mesh, bvh, kRaysPerCase, 77);
  EXPECT_GE(count.rays, kRaysPerCase);
  EXPECT_EQ(count.leaks, 0) << "of " << count.rays << " rays; first " << count.first;
}

// Every combination of offset and scale where the mesh still exists in float: a mesh 1e-4
// across at 1e3 (float spacing 6e-5), or 1e-4 or 1e-2 across at 1e6 (spacing 0.06), rounds
// to a handful of points, with no inside left to aim at. Those cases are in EXTREME_CASES.md
// as not representable.
std::vector<ExtremeCase> Cases() {
  std::vector<ExtremeCase> cases;
  for (MeshShape shape : {MeshShape::kCube, MeshShape::kSphere, MeshShape::kScan}) {
    for (double translate : {0.0, 1e3, 1e6}) {
      for (double scale : {1e-4, 1e-2, 1.0, 1e2, 1e5}) {
        const double spacing = translate == 0 ? 0 : std::ldexp(1.0, std::ilogb(translate) - 23);
        if (scale < 64 * spacing) continue;
        cases.push_back({shape, scale, translate});
      }
    }
  }
  return cases;
}

INSTANTIATE_TEST_SUITE_P(
    Meshes, ExtremeWatertight, ::testing::ValuesIn(Cases()),
    [](const ::testing::TestParamInfo<ExtremeCase>& param_info) {
      const ExtremeCase& c = param_info.param;
      return ShapeName(c.shape) + "Scale" + Sci(c.scale) + "At" + Sci(c.translate);
    });

TEST(ExtremeWatertight, CasesCoverAMillionRaysPerMesh) {
  EXPECT_GE(Cases().size() / 3 * kRaysPerCase, 1000000u);
}

// The harness sees a crack: the same rays with one triangle left out do leak.
TEST(ExtremeWatertight, HarnessDetectsAMissingTriangle) {
  const ClosedMesh mesh = MakeClosedMesh(MeshShape::kScan, 10, 1e2, 1e3);
  const MeshBvh bvh(mesh.triangles, 123);
  EXPECT_GT(Shoot(mesh, bvh, kRaysPerCase, 77).leaks, 0);
}

}  // namespace
}  // namespace raystack::geometry_test
