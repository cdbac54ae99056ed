// Measures BuildBvh on block-sized inputs and closest-hit traversal speed. Not a test: it
// asserts nothing and prints timings (run it on a quiet machine).

#include <chrono>
#include <cstdio>
#include <random>
#include <vector>

#include "common/geometry/bvh.h"
#include "common/geometry/triangle.h"
#include "tests/geometry/test_meshes.h"

namespace raystack {
namespace {

using Clock = std::chrono::steady_clock;
using geometry_test::Triangle;

std::vector<Triangle> Soup(int n, bool clustered, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(-1, 1);
  std::normal_distribution<float> spread(0, 0.05f);
  std::vector<Triangle> tris;
  for (int i = 0; i < n; ++i) {
    Vec3f c{unit(rng), unit(rng), unit(rng)};
    if (clustered) c = Vec3f{float(i % 7), 0, 0} + Vec3f{spread(rng), spread(rng), spread(rng)};
    Triangle t;
    for (Vec3f& p : t.p) p = c + Vec3f{unit(rng), unit(rng), unit(rng)} * 0.05f;
    tris.push_back(t);
  }
  return tris;
}

void Run(const char* name, int n, bool clustered) {
  const std::vector<Triangle> tris = Soup(n, clustered, 7);
  std::vector<BvhBuildPrimitive> prims;
  for (const Triangle& t : tris) {
    Bounds3f b;
    for (const Vec3f& p : t.p) b.Extend(p);
    prims.push_back({b});
  }
  std::vector<uint32_t> order;
  std::vector<BvhNode> nodes;
  const int builds = 2000;
  const auto t0 = Clock::now();
  for (int i = 0; i < builds; ++i) nodes = BuildBvh(prims, BvhBuildOptions{}, &order);
  const double build_us =
      std::chrono::duration<double, std::micro>(Clock::now() - t0).count() / builds;

  std::mt19937 rng(3);
  std::uniform_real_distribution<float> unit(-1, 1);
  const int rays = 200000;
  int hits = 0;
  const auto t1 = Clock::now();
  for (int r = 0; r < rays; ++r) {
    const Triangle& target = tris[static_cast<size_t>(r) % tris.size()];
    const Vec3f origin{unit(rng) * 3, unit(rng) * 3, 3};
    const Ray ray{origin, target.p[0] - origin};
    const RayTriangleSetup setup(ray);
    float tmax = ray.tmax;
    uint32_t best = kInvalidId;
    TraverseBvh(nodes, ray, 3.0f, &tmax, [&](uint32_t first, uint32_t count) {
      for (uint32_t i = first; i < first + count; ++i) {
        const Triangle& t = tris[order[i]];
        float th, u, v;
        if (IntersectTriangle(setup, t.p[0], t.p[1], t.p[2], ray.tmin, tmax, &th, &u, &v)) {
          tmax = th;
          best = order[i];
        }
      }
      return false;
    });
    hits += best != kInvalidId;
  }
  const double ray_ns =
      std::chrono::duration<double, std::nano>(Clock::now() - t1).count() / rays;
  std::printf("%-10s n=%5d  build %7.1f us (%5.1f ns/prim), %5zu nodes  |  closest hit %6.1f ns/ray (%d%% hit)\n",
              name, n, build_us, build_us * 1e3 / n, nodes.size(), ray_ns, hits * 100 / rays);
}

}  // namespace
}  // namespace raystack

int main() {
  for (int n : {1000, 2000, 3000}) {
    raystack::Run("uniform", n, false);
    raystack::Run("clustered", n, true);
  }
}
