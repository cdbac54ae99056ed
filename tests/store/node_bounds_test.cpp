// The walks skip octree children whose blocks' bounds a ray misses, testing 4 children at a
// time (KeepMayHit, SSE2). Skipping must be exact: the packed test answers as MayHit, the
// single-box test a block's BVH makes of its root, for every child, on hostile rays too (axis-
// parallel, through box faces, zero-size boxes, infinite and finite hit distances).

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "common/store/octree.h"

namespace raystack::store {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

TEST(NodeBounds, PackedTestAnswersAsTheSingleBoxTestForEveryChild) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-1, 1);
  // 8 children in six float arrays, as StoreReader lays them out; boxes on a grid of a few
  // values so rays often pass exactly through faces, edges and corners; some empty or flat.
  const float grid[] = {-1.0f, -0.5f, 0.0f, 0.25f, 0.5f, 1.0f};
  std::uniform_int_distribution<int> g(0, 5);
  size_t kept = 0, dropped = 0;
  for (int trial = 0; trial < 4000; ++trial) {
    std::vector<float> arrays(6 * 8);
    for (int c = 0; c < 8; ++c) {
      for (int a = 0; a < 3; ++a) {
        float lo = grid[g(rng)], hi = grid[g(rng)];
        if (lo > hi) std::swap(lo, hi);
        arrays[a * 8 + c] = lo;
        arrays[(3 + a) * 8 + c] = hi;
      }
      if (trial % 7 == c) {  // an empty child (a node with no blocks)
        for (int a = 0; a < 3; ++a) {
          arrays[a * 8 + c] = kInf;
          arrays[(3 + a) * 8 + c] = -kInf;
        }
      }
    }
    NodeBounds bounds;
    for (int a = 0; a < 3; ++a) {
      bounds.lower[a] = arrays.data() + a * 8;
      bounds.upper[a] = arrays.data() + (3 + a) * 8;
    }
    Ray ray;
    ray.origin = {grid[g(rng)] * 1.5f, u(rng) * 2, grid[g(rng)] * 2};
    ray.direction = {u(rng), u(rng), u(rng)};
    if (trial % 3 == 0) ray.direction[trial % 9 / 3] = 0.0f;  // axis-parallel in that axis
    if (trial % 5 == 0) ray.direction = {0, 0, trial % 2 ? 1.0f : -1.0f};
    ray.tmin = 0;
    const float t_best = trial % 4 == 0 ? kInf : std::fabs(u(rng)) * 3;
    const RayBoxSetup setup(ray, 3.0f);  // with a margin, as the store's walks
    const uint32_t all = (trial % 11 == 0) ? 0x5au : 0xffu;  // some children already dropped
    const uint32_t keep = KeepMayHit(setup, bounds, 0, all, ray.tmin, t_best);
    for (uint32_t c = 0; c < 8; ++c) {
      const bool expected = ((all >> c) & 1u) && MayHit(setup, bounds[c], ray.tmin, t_best);
      ASSERT_EQ(((keep >> c) & 1u) != 0, expected) << "trial " << trial << " child " << c;
      (expected ? kept : dropped) += 1;
    }
  }
  EXPECT_GT(kept, 500u);  // both answers occur often
  EXPECT_GT(dropped, 1000u);
}

}  // namespace
}  // namespace raystack::store
