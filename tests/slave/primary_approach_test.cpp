// A far camera's primary rays start near the model (primary_approach.h): the moved ray meets
// the model's box exactly when the camera's ray does, from 1e3 to 1e17 model sizes away, at
// oblique angles and with the model off the world's origin; near cameras keep their rays.

#include "slave/primary_approach.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace raystack::slave {
namespace {

// Whether the line from `o` along `d` enters the box [lo, hi] ahead of o, in long double (64
// bits: at 1e17 its slab distances are good to ~1e-2 of a unit box); `margin` is how far
// inside the box the ray passes at least (so grazing rays, which rounding may decide either
// way, are left out by the caller).
bool MeetsBox(const long double o[3], const long double d[3], const long double lo[3],
              const long double hi[3], long double* margin) {
  long double enter = 0, leave = INFINITY;
  for (int a = 0; a < 3; ++a) {
    long double t0 = (lo[a] - o[a]) / d[a], t1 = (hi[a] - o[a]) / d[a];
    if (t0 > t1) std::swap(t0, t1);
    enter = std::max(enter, t0);
    leave = std::min(leave, t1);
  }
  // How deep inside the box the ray's middle point within it lies (negative: outside).
  const long double mid = 0.5L * (enter + std::min(leave, enter + 1e30L));
  *margin = INFINITY;
  for (int a = 0; a < 3; ++a) {
    const long double p = o[a] + d[a] * mid;
    *margin = std::min({*margin, p - lo[a], hi[a] - p});
  }
  return enter <= leave;
}

TEST(PrimaryApproach, TheMovedRayMeetsTheModelExactlyWhenTheCamerasRayDoes) {
  std::mt19937 rng(7);
  std::normal_distribution<double> gauss;
  std::uniform_real_distribution<double> unit(-1, 1);
  int checked = 0, met = 0, disagree = 0;
  for (const double centre : {0.0, 5.5, 1000.25}) {
    const Bounds3f box{{static_cast<float>(centre - 0.5), static_cast<float>(centre - 0.5),
                        static_cast<float>(centre - 0.5)},
                       {static_cast<float>(centre + 0.5), static_cast<float>(centre + 0.5),
                        static_cast<float>(centre + 0.5)}};
    for (const double distance : {1e3, 1e5, 5e6, 3e7, 1e12, 1e17}) {
      for (int i = 0; i < 400; ++i) {
        // A camera in a random direction, aiming at a random point near the box.
        double u[3], len = 0;
        for (double& x : u) {
          x = gauss(rng);
          len += x * x;
        }
        Vec3f camera;
        for (int a = 0; a < 3; ++a)
          camera[a] = static_cast<float>(centre + u[a] / std::sqrt(len) * distance);
        const PrimaryApproach approach(box, camera);
        Ray ray;
        ray.origin = camera;
        Vec3f aim;
        for (int a = 0; a < 3; ++a) aim[a] = static_cast<float>(centre + unit(rng));
        ray.direction = Normalize(aim - camera);
        long double o[3], d[3], lo[3], hi[3];
        for (int a = 0; a < 3; ++a) {
          o[a] = camera[a];
          d[a] = ray.direction[a];
          lo[a] = box.lower[a];
          hi[a] = box.upper[a];
        }
        long double depth;
        const bool before = MeetsBox(o, d, lo, hi, &depth);
        if (std::fabs(depth) < 0.05L) continue;  // grazing: either answer is the float ray's
        approach.Approach(&ray);
        ASSERT_NE(ray.origin, camera) << "a camera " << distance << " sizes away is far";
        for (int a = 0; a < 3; ++a) o[a] = ray.origin[a];
        long double moved_depth;
        const bool after = MeetsBox(o, d, lo, hi, &moved_depth);
        // The moved origin is outside the box, and the camera is where it says.
        EXPECT_LT(std::fabs(approach.Skipped(ray.origin) - distance), 8 + distance * 1e-6);
        ++checked;
        met += before;
        if (before != after && ++disagree <= 5)
          ADD_FAILURE() << "centre " << centre << ", " << distance << " sizes: the camera's ray "
                        << (before ? "meets" : "misses") << " the box, the moved one does not";
      }
    }
  }
  EXPECT_GT(checked, 5000);
  EXPECT_GT(met, checked / 8);  // rays aim within a size of the centre: ~1 in 5 meets the box
  EXPECT_EQ(disagree, 0);
}

TEST(PrimaryApproach, ANearCameraKeepsItsRays) {
  const Bounds3f box{{0, 0, 0}, {1, 1, 1}};
  const Vec3f camera{30, 40, 20};  // ~48 sizes away: near
  const PrimaryApproach approach(box, camera);
  Ray ray;
  ray.origin = camera;
  ray.direction = Normalize(Vec3f{0.5f, 0.5f, 0.5f} - camera);
  approach.Approach(&ray);
  EXPECT_EQ(ray.origin, camera);
  EXPECT_EQ(approach.Skipped(ray.origin), 0);
}

}  // namespace
}  // namespace raystack::slave
