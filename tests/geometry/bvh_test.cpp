#include "common/geometry/bvh.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "common/geometry/triangle.h"
#include "tests/geometry/test_meshes.h"

namespace raystack {
namespace {

using geometry_test::Triangle;

constexpr float kInf = std::numeric_limits<float>::infinity();

// ---------------------------------------------------------------------------------------------
// Triangle soups

Bounds3f BoundsOf(const Triangle& t) {
  Bounds3f b;
  for (const Vec3f& p : t.p) b.Extend(p);
  return b;
}

std::vector<BvhBuildPrimitive> PrimitivesOf(const std::vector<Triangle>& triangles) {
  std::vector<BvhBuildPrimitive> prims;
  for (const Triangle& t : triangles) prims.push_back({BoundsOf(t)});
  return prims;
}

Vec3f RandomVec(std::mt19937& rng, float lo, float hi) {
  std::uniform_real_distribution<float> d(lo, hi);
  const float x = d(rng), y = d(rng), z = d(rng);
  return {x, y, z};
}

Triangle RandomTriangleAround(std::mt19937& rng, Vec3f center, float size) {
  return {{center + RandomVec(rng, -size, size), center + RandomVec(rng, -size, size),
           center + RandomVec(rng, -size, size)}};
}

std::vector<Triangle> UniformSoup(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<Triangle> tris;
  for (int i = 0; i < n; ++i) tris.push_back(RandomTriangleAround(rng, RandomVec(rng, -1, 1), 0.1f));
  return tris;
}

std::vector<Triangle> ClusteredSoup(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<Vec3f> centers;
  for (int c = 0; c < 5; ++c) centers.push_back(RandomVec(rng, -10, 10));
  std::normal_distribution<float> spread(0, 0.05f);
  std::vector<Triangle> tris;
  for (int i = 0; i < n; ++i) {
    const Vec3f c = centers[i % centers.size()];
    const Vec3f at{c.x + spread(rng), c.y + spread(rng), c.z + spread(rng)};
    tris.push_back(RandomTriangleAround(rng, at, 0.01f));
  }
  return tris;
}

// Coplanar duplicates: every hit is a tie, resolved by the smallest id.
std::vector<Triangle> IdenticalSoup(int n) {
  return std::vector<Triangle>(n, Triangle{{{-1, -1, 0.5f}, {1, -0.5f, 0.25f}, {0, 1, -0.5f}}});
}

// Boxes of zero extent: points (never hit), and triangles flat in x, y or z, some of them
// sharing planes so axis-parallel rays lie exactly in their slab planes.
std::vector<Triangle> ZeroExtentSoup(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> grid(-4, 4);
  std::vector<Triangle> tris;
  for (int i = 0; i < n; ++i) {
    const Vec3f base{grid(rng) * 0.25f, grid(rng) * 0.25f, grid(rng) * 0.25f};
    if (i % 4 == 0) {
      tris.push_back({{base, base, base}});
      continue;
    }
    Triangle t = RandomTriangleAround(rng, base, 0.2f);
    const int flat_axis = i % 3;
    for (Vec3f& p : t.p) p[flat_axis] = base[flat_axis];
    tris.push_back(t);
  }
  return tris;
}

std::vector<Triangle> HugeAmongSmall(int n, uint32_t seed) {
  std::vector<Triangle> tris = UniformSoup(n - 1, seed);
  const Triangle huge{{{-100, -100, -3}, {100, -90, 2}, {-20, 100, 1}}};
  tris.insert(tris.begin() + static_cast<long>(tris.size() / 2), huge);
  return tris;
}

struct Soup {
  std::string name;
  std::vector<Triangle> triangles;
};

std::vector<Soup> AllSoups() {
  return {
      {"Uniform", UniformSoup(2000, 1)},
      {"Clustered", ClusteredSoup(2000, 2)},
      {"Identical", IdenticalSoup(300)},
      {"ZeroExtent", ZeroExtentSoup(1000, 3)},
      {"HugeAmongSmall", HugeAmongSmall(1000, 4)},
      {"Single", UniformSoup(1, 5)},
      {"Empty", {}},
  };
}

// ---------------------------------------------------------------------------------------------
// Structure checks

struct TreeCheck {
  int max_depth = 0;
  int leaves = 0;
  uint32_t next_preorder = 0;
};

// Walks the subtree at `index` in preorder and checks it; returns the union of its primitives'
// bounds. `ancestors` holds the nodes above, so every primitive is checked against each.
Bounds3f CheckSubtree(std::span<const BvhNode> nodes, const std::vector<uint32_t>& order,
                      std::span<const BvhBuildPrimitive> prims, const BvhBuildOptions& options,
                      uint32_t index, int depth, std::vector<uint32_t>* ancestors,
                      std::vector<int>* covered, TreeCheck* check) {
  Bounds3f subtree;
  if (index >= nodes.size()) {
    ADD_FAILURE() << "node index " << index << " out of " << nodes.size();
    return subtree;
  }
  // Depth-first layout: preorder visiting gives the indices 0, 1, 2, ...
  EXPECT_EQ(index, check->next_preorder++);
  check->max_depth = std::max(check->max_depth, depth);
  if (depth > kBvhMaxDepth) {
    ADD_FAILURE() << "depth " << depth;
    return subtree;
  }
  const BvhNode& node = nodes[index];
  EXPECT_EQ(node.pad, 0);
  if (node.count == 0) {
    EXPECT_LT(node.axis, 3);
    EXPECT_GT(node.offset, index + 1);
    ancestors->push_back(index);
    subtree.Extend(CheckSubtree(nodes, order, prims, options, index + 1, depth + 1, ancestors,
                                covered, check));
    EXPECT_EQ(node.offset, check->next_preorder) << "second child must follow the first subtree";
    subtree.Extend(CheckSubtree(nodes, order, prims, options, node.offset, depth + 1, ancestors,
                                covered, check));
    ancestors->pop_back();
  } else {
    ++check->leaves;
    EXPECT_LE(node.count, options.max_leaf_size);
    EXPECT_LE(uint64_t{node.offset} + node.count, order.size());
    for (uint32_t i = node.offset; i < node.offset + node.count && i < order.size(); ++i) {
      ++(*covered)[i];
      const Bounds3f& b = prims[order[i]].bounds;
      subtree.Extend(b);
      for (uint32_t a : *ancestors) {
        const BvhNode& up = nodes[a];
        for (int k = 0; k < 3; ++k) {
          EXPECT_LE(up.lower[k], b.lower[k]) << "prim " << order[i] << " outside node " << a;
          EXPECT_GE(up.upper[k], b.upper[k]) << "prim " << order[i] << " outside node " << a;
        }
      }
    }
  }
  // Node bounds are exactly the union of the primitives below, not merely conservative.
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(node.lower[k], subtree.lower[k]) << "node " << index;
    EXPECT_EQ(node.upper[k], subtree.upper[k]) << "node " << index;
  }
  return subtree;
}

TreeCheck CheckTree(const std::vector<BvhNode>& nodes, const std::vector<uint32_t>& order,
                    std::span<const BvhBuildPrimitive> prims, const BvhBuildOptions& options) {
  TreeCheck check;
  EXPECT_EQ(order.size(), prims.size());
  std::vector<int> seen(prims.size(), 0);
  for (uint32_t p : order) {
    if (p < seen.size()) ++seen[p];
  }
  EXPECT_EQ(std::count(seen.begin(), seen.end(), 1), static_cast<long>(prims.size()))
      << "order is not a permutation";
  if (prims.empty()) {
    EXPECT_TRUE(nodes.empty());
    return check;
  }
  EXPECT_LE(nodes.size(), 2 * prims.size() - 1);
  std::vector<uint32_t> ancestors;
  std::vector<int> covered(order.size(), 0);
  CheckSubtree(nodes, order, prims, options, 0, 0, &ancestors, &covered, &check);
  EXPECT_EQ(check.next_preorder, nodes.size()) << "unreachable nodes";
  EXPECT_EQ(std::count(covered.begin(), covered.end(), 1), static_cast<long>(order.size()))
      << "leaves must cover every slot of order exactly once";
  return check;
}

// ---------------------------------------------------------------------------------------------
// Closest hit and any hit, by brute force and through the BVH

bool Intersect(const RayTriangleSetup& setup, const Triangle& tri, const Ray& ray, float* t,
               float* u, float* v) {
  return IntersectTriangle(setup, tri.p[0], tri.p[1], tri.p[2], ray.tmin, ray.tmax, t, u, v);
}

Hit BruteForceClosest(const std::vector<Triangle>& tris, const Ray& ray) {
  const RayTriangleSetup setup(ray);
  Hit best;
  for (uint32_t id = 0; id < tris.size(); ++id) {
    float t, u, v;
    if (Intersect(setup, tris[id], ray, &t, &u, &v) && CloserThan(t, id, best)) {
      best.t = t, best.u = u, best.v = v, best.triangle_id = id;
    }
  }
  return best;
}

bool BruteForceOccluded(const std::vector<Triangle>& tris, const Ray& ray) {
  const RayTriangleSetup setup(ray);
  for (const Triangle& tri : tris) {
    float t, u, v;
    if (Intersect(setup, tri, ray, &t, &u, &v)) return true;
  }
  return false;
}

struct BuiltSoup {
  std::vector<Triangle> tris;
  std::vector<BvhNode> nodes;
  std::vector<uint32_t> order;

  // The largest |coordinate| of its triangles, for the box tests' margin.
  float Magnitude() const {
    float m = 0;
    for (const Triangle& t : tris)
      for (const Vec3f& p : t.p) m = std::max({m, std::fabs(p.x), std::fabs(p.y), std::fabs(p.z)});
    return m;
  }
};

Hit BvhClosest(const BuiltSoup& s, const Ray& ray) {
  const RayTriangleSetup setup(ray);
  Hit best;
  float tmax = ray.tmax;
  TraverseBvh(s.nodes, ray, s.Magnitude(), &tmax, [&](uint32_t first, uint32_t count) {
    for (uint32_t i = first; i < first + count; ++i) {
      const uint32_t id = s.order[i];
      float t, u, v;
      // The full ray interval, not tmax: a tie at t == tmax can still win on id.
      if (Intersect(setup, s.tris[id], ray, &t, &u, &v) && CloserThan(t, id, best)) {
        best.t = t, best.u = u, best.v = v, best.triangle_id = id;
        tmax = t;
      }
    }
    return false;
  });
  return best;
}

bool BvhOccluded(const BuiltSoup& s, const Ray& ray) {
  const RayTriangleSetup setup(ray);
  bool occluded = false;
  float tmax = ray.tmax;
  TraverseBvh(s.nodes, ray, s.Magnitude(), &tmax, [&](uint32_t first, uint32_t count) {
    for (uint32_t i = first; i < first + count; ++i) {
      float t, u, v;
      if (Intersect(setup, s.tris[s.order[i]], ray, &t, &u, &v)) return occluded = true;
    }
    return false;
  });
  return occluded;
}

Vec3f PointOn(std::mt19937& rng, const Triangle& t) {
  std::uniform_real_distribution<float> unit(0, 1);
  float a = unit(rng), b = unit(rng);
  if (a + b > 1) a = 1 - a, b = 1 - b;
  return t.p[0] + (t.p[1] - t.p[0]) * a + (t.p[2] - t.p[0]) * b;
}

// A mix of rays: aimed at triangles from outside and inside the scene, random, starting on
// vertices (on box faces), and axis-parallel ones with exact zero (+0 or -0) components, some
// of which lie exactly in the slab planes of flat triangles.
std::vector<Ray> MakeRays(const std::vector<Triangle>& tris, int n, uint32_t seed) {
  Bounds3f scene;
  for (const Triangle& t : tris) scene.Extend(BoundsOf(t));
  if (scene.Empty()) scene = {{-1, -1, -1}, {1, 1, 1}};
  const Vec3f center = scene.Center();
  const float radius = std::max(Length(scene.Extent()), 1e-3f);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0, 1);
  std::uniform_int_distribution<size_t> pick(0, tris.empty() ? 0 : tris.size() - 1);
  std::normal_distribution<float> gauss(0, 1);
  auto inside = [&] {
    return scene.lower + scene.Extent() * Vec3f{unit(rng), unit(rng), unit(rng)};
  };
  auto target = [&] { return tris.empty() ? center : PointOn(rng, tris[pick(rng)]); };
  auto signed_zero = [&] { return unit(rng) < 0.5f ? 0.0f : -0.0f; };

  std::vector<Ray> rays;
  for (int i = 0; i < n; ++i) {
    Ray ray;
    switch (i % 6) {
      case 0: {  // from outside at a point on a triangle
        const Vec3f dir = Normalize(Vec3f{gauss(rng), gauss(rng), gauss(rng)});
        ray.origin = center + dir * (radius * 1.5f);
        ray.direction = target() - ray.origin;
        break;
      }
      case 1:  // from inside the boxes, anywhere
        ray.origin = inside();
        ray.direction = {gauss(rng), gauss(rng), gauss(rng)};
        break;
      case 2:  // from inside at a vertex
        ray.origin = inside();
        ray.direction = (tris.empty() ? center : tris[pick(rng)].p[i % 3]) - ray.origin;
        break;
      case 3: {  // along an axis through a point on a triangle
        const Vec3f at = target();
        const int axis = static_cast<int>(unit(rng) * 3) % 3;
        const float sign = unit(rng) < 0.5f ? 1.0f : -1.0f;
        ray.origin = at;
        ray.origin[axis] -= sign * radius;
        ray.direction = {signed_zero(), signed_zero(), signed_zero()};
        ray.direction[axis] = sign;
        break;
      }
      case 4: {  // one zero component: the ray stays in the plane through a triangle point
        const Vec3f at = target();
        const int axis = static_cast<int>(unit(rng) * 3) % 3;
        ray.direction = {gauss(rng), gauss(rng), gauss(rng)};
        ray.direction[axis] = signed_zero();
        ray.origin = at - ray.direction * radius;
        ray.origin[axis] = at[axis];
        break;
      }
      default:  // starting exactly on a vertex, which lies on the faces of its boxes
        ray.origin = tris.empty() ? center : tris[pick(rng)].p[i % 3];
        ray.direction = {gauss(rng), gauss(rng), gauss(rng)};
        break;
    }
    if (i % 4 == 1) ray.tmax = unit(rng) * 2;  // a finite segment, t in units of |direction|
    if (i % 7 == 3) ray.tmin = unit(rng) * 0.1f;
    rays.push_back(ray);
  }
  return rays;
}

std::string Describe(const Ray& r) {
  char buf[256];
  using D = double;
  std::snprintf(buf, sizeof buf, "o=(%a %a %a) d=(%a %a %a) t=[%a %a]", D{r.origin.x},
                D{r.origin.y}, D{r.origin.z}, D{r.direction.x}, D{r.direction.y},
                D{r.direction.z}, D{r.tmin}, D{r.tmax});
  return buf;
}

// ---------------------------------------------------------------------------------------------
// Tests

struct BuildCase {
  int max_leaf_size;
  int bins;
};

class BvhOnSoups : public ::testing::TestWithParam<BuildCase> {
 protected:
  BvhBuildOptions Options() const {
    BvhBuildOptions options;
    options.max_leaf_size = GetParam().max_leaf_size;
    options.bins = GetParam().bins;
    return options;
  }
};

TEST_P(BvhOnSoups, StructureIsValid) {
  for (const Soup& soup : AllSoups()) {
    SCOPED_TRACE(soup.name);
    const std::vector<BvhBuildPrimitive> prims = PrimitivesOf(soup.triangles);
    std::vector<uint32_t> order;
    const std::vector<BvhNode> nodes = BuildBvh(prims, Options(), &order);
    const TreeCheck check = CheckTree(nodes, order, prims, Options());
    EXPECT_LE(check.max_depth, kBvhMaxDepth);
    if (!prims.empty()) {
      EXPECT_GE(check.leaves * Options().max_leaf_size, static_cast<int>(prims.size()));
    }
  }
}

TEST_P(BvhOnSoups, ClosestAndAnyHitEqualBruteForce) {
  for (const Soup& soup : AllSoups()) {
    SCOPED_TRACE(soup.name);
    BuiltSoup s{soup.triangles, {}, {}};
    s.nodes = BuildBvh(PrimitivesOf(s.tris), Options(), &s.order);
    int hits = 0, closest_mismatches = 0, occlusion_mismatches = 0;
    for (const Ray& ray : MakeRays(s.tris, 10000, 99)) {
      const Hit expected = BruteForceClosest(s.tris, ray);
      const Hit got = BvhClosest(s, ray);
      hits += expected.Valid();
      const bool same = std::bit_cast<uint32_t>(expected.t) == std::bit_cast<uint32_t>(got.t) &&
                        expected.triangle_id == got.triangle_id &&
                        std::bit_cast<uint32_t>(expected.u) == std::bit_cast<uint32_t>(got.u) &&
                        std::bit_cast<uint32_t>(expected.v) == std::bit_cast<uint32_t>(got.v);
      if (!same && closest_mismatches++ < 3) {
        ADD_FAILURE() << "closest hit differs for " << Describe(ray) << ": brute force id "
                      << expected.triangle_id << " t " << expected.t << ", BVH id "
                      << got.triangle_id << " t " << got.t;
      }
      const bool occluded = BvhOccluded(s, ray);
      if (occluded != BruteForceOccluded(s.tris, ray) && occlusion_mismatches++ < 3) {
        ADD_FAILURE() << "occlusion differs for " << Describe(ray) << ": BVH says " << occluded;
      }
      // Any-hit finds a hit exactly when closest-hit does.
      EXPECT_EQ(occluded, expected.Valid());
    }
    EXPECT_EQ(closest_mismatches, 0);
    EXPECT_EQ(occlusion_mismatches, 0);
    // The rays must actually exercise hits wherever there is something to hit.
    if (s.tris.size() > 1) {
      EXPECT_GT(hits, 1000);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Options, BvhOnSoups,
                         ::testing::Values(BuildCase{4, 16}, BuildCase{1, 16}, BuildCase{8, 2},
                                           BuildCase{16, 64}),
                         [](const ::testing::TestParamInfo<BuildCase>& param_info) {
                           const BuildCase& c = param_info.param;
                           return "Leaf" + std::to_string(c.max_leaf_size) + "Bins" +
                                  std::to_string(c.bins);
                         });

TEST(BuildBvh, EmptyInputGivesNoNodes) {
  std::vector<uint32_t> order{7, 8};
  EXPECT_TRUE(BuildBvh({}, BvhBuildOptions{}, &order).empty());
  EXPECT_TRUE(order.empty());
}

TEST(BuildBvh, SinglePrimitiveIsOneLeaf) {
  const std::vector<BvhBuildPrimitive> prims{{{{1, 2, 3}, {4, 5, 6}}}};
  std::vector<uint32_t> order;
  const std::vector<BvhNode> nodes = BuildBvh(prims, BvhBuildOptions{}, &order);
  ASSERT_EQ(nodes.size(), 1u);
  EXPECT_EQ(nodes[0].count, 1);
  EXPECT_EQ(nodes[0].offset, 0u);
  EXPECT_EQ(nodes[0].lower[1], 2.0f);
  EXPECT_EQ(nodes[0].upper[2], 6.0f);
  EXPECT_EQ(order, std::vector<uint32_t>{0});
}

TEST(BuildBvh, IsDeterministic) {
  const std::vector<BvhBuildPrimitive> prims = PrimitivesOf(ClusteredSoup(3000, 17));
  std::vector<uint32_t> order_a, order_b;
  const std::vector<BvhNode> a = BuildBvh(prims, BvhBuildOptions{}, &order_a);
  const std::vector<BvhNode> b = BuildBvh(prims, BvhBuildOptions{}, &order_b);
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size() * sizeof(BvhNode)), 0);
  EXPECT_EQ(order_a, order_b);
}

// Large enough for the parallel build (at least 65,536 primitives): on any number of threads
// the tree and the order are the ones one thread builds, bit for bit, on SAH splits, on median
// splits (identical boxes) and on leaves larger than the subtrees the threads take.
TEST(BuildBvh, ThreadsBuildTheSameTree) {
  const std::vector<std::vector<BvhBuildPrimitive>> inputs = {
      PrimitivesOf(UniformSoup(150000, 3)), PrimitivesOf(ClusteredSoup(100000, 4)),
      std::vector<BvhBuildPrimitive>(70000, {{{1, 1, 1}, {2, 2, 2}}})};
  for (size_t k = 0; k < inputs.size(); ++k) {
    for (int leaf : {4, 30000}) {
      BvhBuildOptions options;
      options.max_leaf_size = leaf;
      std::vector<uint32_t> order_one;
      const std::vector<BvhNode> one = BuildBvh(inputs[k], options, &order_one);
      for (int threads : {2, 3, 8}) {
        SCOPED_TRACE(testing::Message() << "input " << k << ", leaves of " << leaf << ", "
                                        << threads << " threads");
        options.threads = threads;
        std::vector<uint32_t> order;
        const std::vector<BvhNode> nodes = BuildBvh(inputs[k], options, &order);
        ASSERT_EQ(nodes.size(), one.size());
        EXPECT_EQ(std::memcmp(nodes.data(), one.data(), one.size() * sizeof(BvhNode)), 0);
        EXPECT_EQ(order, order_one);
      }
    }
  }
}

TEST(BuildBvh, SeparatesTwoDistantClusters) {
  // SAH must put the split between the clusters: the root's children are the two clusters.
  std::vector<Triangle> tris = ClusteredSoup(64, 5);
  std::vector<BvhBuildPrimitive> prims;
  for (int i = 0; i < 64; ++i) {
    const float x = i < 32 ? -100.0f : 100.0f;
    prims.push_back({{{x, 0, 0}, {x + 1, 1, 1}}});
  }
  std::vector<uint32_t> order;
  const std::vector<BvhNode> nodes = BuildBvh(prims, BvhBuildOptions{}, &order);
  ASSERT_GT(nodes.size(), 1u);
  EXPECT_EQ(nodes[0].axis, 0);
  EXPECT_EQ(nodes[1].upper[0], -99.0f);
  EXPECT_EQ(nodes[nodes[0].offset].lower[0], 100.0f);
}

TEST(BuildBvh, DepthStaysBoundedOnExponentialSpacing) {
  // Boxes at +-2^k: every binned SAH split peels off only the outermost boxes, which would
  // make a chain hundreds of levels deep without the depth bound.
  std::vector<BvhBuildPrimitive> prims;
  for (int k = -120; k <= 120; ++k) {
    for (float sign : {1.0f, -1.0f}) {
      const float x = sign * std::ldexp(1.0f, k);
      prims.push_back({{{x, 0, 0}, {x, 0, 0}}});
    }
  }
  for (int leaf : {1, 2}) {
    BvhBuildOptions options;
    options.max_leaf_size = leaf;
    std::vector<uint32_t> order;
    const std::vector<BvhNode> nodes = BuildBvh(prims, options, &order);
    const TreeCheck check = CheckTree(nodes, order, prims, options);
    EXPECT_LE(check.max_depth, kBvhMaxDepth);
    EXPECT_GT(check.max_depth, 20) << "the input no longer stresses the depth bound";
  }
}

TEST(BuildBvh, IdenticalBoxesSplitByIndexIntoFullLeaves) {
  const std::vector<BvhBuildPrimitive> prims(1000, {{{1, 1, 1}, {2, 2, 2}}});
  BvhBuildOptions options;
  options.max_leaf_size = 8;
  std::vector<uint32_t> order;
  const std::vector<BvhNode> nodes = BuildBvh(prims, options, &order);
  const TreeCheck check = CheckTree(nodes, order, prims, options);
  EXPECT_LE(check.max_depth, 8);  // balanced: ceil(log2(1000 / 8)) = 7 levels of splits
  EXPECT_LE(check.leaves, 1000 / 8 * 2);
}

TEST(BuildBvh, LargestLeavesFitTheCountField) {
  const std::vector<BvhBuildPrimitive> prims(70000, {{{0, 0, 0}, {0, 0, 0}}});
  BvhBuildOptions options;
  options.max_leaf_size = 65535;
  std::vector<uint32_t> order;
  const std::vector<BvhNode> nodes = BuildBvh(prims, options, &order);
  CheckTree(nodes, order, prims, options);
  ASSERT_EQ(nodes.size(), 3u);
  EXPECT_EQ(nodes[1].count + nodes[2].count, 70000);
}

// ---------------------------------------------------------------------------------------------
// Box test

bool Box(const Ray& ray, Bounds3f b, float* t_enter = nullptr) {
  float t;
  const float lower[3] = {b.lower.x, b.lower.y, b.lower.z};
  const float upper[3] = {b.upper.x, b.upper.y, b.upper.z};
  const bool hit = IntersectBox(RayBoxSetup(ray, 0), lower, upper, ray.tmin, ray.tmax, &t);
  if (hit && t_enter) *t_enter = t;
  return hit;
}

// The entry is the near face's, less the margin (2^-17 of the origin's magnitude here, in t).
TEST(IntersectBox, EntersAtTheNearFaceLessTheMargin) {
  float t = -1;
  const Ray from_left{{-3, 0.5f, 0.5f}, {1, 0, 0}};
  const float pad_left = RayBoxSetup(from_left, 0).pad[0];
  EXPECT_GT(pad_left, 0.0f);
  EXPECT_LT(pad_left, 1e-4f);
  EXPECT_TRUE(Box(from_left, {{0, 0, 0}, {1, 1, 1}}, &t));
  EXPECT_EQ(t, 3.0f - pad_left);
  const Ray from_right{{4, 0.5f, 0.5f}, {-2, 0, 0}};
  EXPECT_TRUE(Box(from_right, {{0, 0, 0}, {1, 1, 1}}, &t));
  EXPECT_EQ(t, 1.5f - RayBoxSetup(from_right, 0).pad[0]);
}

TEST(IntersectBox, OriginInsideEntersAtTmin) {
  float t = -1;
  Ray ray{{0.5f, 0.5f, 0.5f}, {0.3f, -1, 0.2f}};
  ray.tmin = 0.01f;
  EXPECT_TRUE(Box(ray, {{0, 0, 0}, {1, 1, 1}}, &t));
  EXPECT_EQ(t, 0.01f);
}

TEST(IntersectBox, RespectsTheRayInterval) {
  Ray ray{{-3, 0.5f, 0.5f}, {1, 0, 0}};
  ray.tmax = 2.5f;
  EXPECT_FALSE(Box(ray, {{0, 0, 0}, {1, 1, 1}}));
  ray.tmax = kInf;
  ray.direction = {-1, 0, 0};
  EXPECT_FALSE(Box(ray, {{0, 0, 0}, {1, 1, 1}}));  // behind the origin
}

TEST(IntersectBox, RayInsideASlabPlaneHits) {
  // The ray runs in the plane y = 0, the box's lower y face: 0 * inf must not make it miss.
  for (float zero : {0.0f, -0.0f}) {
    EXPECT_TRUE(Box({{-3, 0, 0.5f}, {1, zero, 0}}, {{0, 0, 0}, {1, 1, 1}}));
    EXPECT_TRUE(Box({{-3, 1, 0.5f}, {1, zero, 0}}, {{0, 0, 0}, {1, 1, 1}}));
    EXPECT_TRUE(Box({{-3, 1, 1}, {1, zero, zero}}, {{0, 0, 0}, {1, 1, 1}}));  // along an edge
    EXPECT_FALSE(Box({{-3, 1.0001f, 0.5f}, {1, zero, 0}}, {{0, 0, 0}, {1, 1, 1}}));
    // A flat box, the ray in its plane.
    EXPECT_TRUE(Box({{0.5f, 0.5f, -2}, {zero, zero, 1}}, {{0, 0.5f, 0}, {1, 0.5f, 1}}));
  }
}

TEST(IntersectBox, AxisParallelRaysHitPointBoxesAndMissBeside) {
  const Bounds3f point{{2, 3, 4}, {2, 3, 4}};
  EXPECT_TRUE(Box({{2, 3, -10}, {0, 0, 1}}, point));
  EXPECT_TRUE(Box({{2, 3, 10}, {-0.0f, 0, -1}}, point));
  EXPECT_FALSE(Box({{2, 3.0001f, -10}, {0, 0, 1}}, point));
  EXPECT_FALSE(Box({{2, 3, 10}, {0, 0, 1}}, point));  // behind
}

TEST(IntersectBox, GrazingTheCornerHits) {
  // Aimed exactly at the corner (1, 1, 1) of the unit box from many directions: the exact
  // ray touches the box, so the robust test must not cull it.
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> coord(1.5f, 100);
  for (int i = 0; i < 10000; ++i) {
    const Vec3f origin{coord(rng), coord(rng), coord(rng)};
    const Ray ray{origin, Vec3f{1, 1, 1} - origin};
    EXPECT_TRUE(Box(ray, {{0, 0, 0}, {1, 1, 1}})) << Describe(ray);
  }
}

// ---------------------------------------------------------------------------------------------
// Traversal

TEST(TraverseBvh, EmptyTreeVisitsNothing) {
  float tmax = kInf;
  int calls = 0;
  TraverseBvh({}, Ray{{0, 0, 0}, {1, 0, 0}}, 0, &tmax, [&](uint32_t, uint32_t) {
    ++calls;
    return false;
  });
  EXPECT_EQ(calls, 0);
}

// A row of 1000 unit squares across the x axis at x = 0, 1, ..., 999.
BuiltSoup Row() {
  BuiltSoup s;
  for (int i = 0; i < 1000; ++i) {
    const auto x = static_cast<float>(i);
    s.tris.push_back({{{x, -1, -1}, {x, 1, -1}, {x, 1, 1}}});
    s.tris.push_back({{{x, -1, -1}, {x, 1, 1}, {x, -1, 1}}});
  }
  s.nodes = BuildBvh(PrimitivesOf(s.tris), BvhBuildOptions{}, &s.order);
  return s;
}

// The conference room's hit just outside its box (ConferenceRoomHitOutsideItsBox): without the
// box tests' margin every tree over those 5 triangles, whatever the leaf size, bins or input
// order, returned the farther hit.
TEST(TraverseBvh, AHitJustOutsideItsBoxIsNotPruned) {
  const geometry_test::HitOutsideItsBox c = geometry_test::ConferenceRoomHitOutsideItsBox();
  const Ray ray{c.origin, c.direction};
  int perm[5] = {0, 1, 2, 3, 4};
  do {
    for (int leaf : {1, 2, 4}) {
      for (int bins : {2, 16}) {
        BuiltSoup s;
        for (int k : perm) s.tris.push_back(c.triangles[k]);
        BvhBuildOptions options;
        options.max_leaf_size = leaf;
        options.bins = bins;
        s.nodes = BuildBvh(PrimitivesOf(s.tris), options, &s.order);
        const Hit h = BvhClosest(s, ray);
        ASSERT_TRUE(h.Valid());
        EXPECT_EQ(perm[h.triangle_id], 3) << "leaves of " << leaf << ", " << bins << " bins, order "
                                          << perm[0] << perm[1] << perm[2] << perm[3] << perm[4];
        EXPECT_EQ(h.t, 0x1.ffffe8p-1f);
      }
    }
  } while (std::next_permutation(perm, perm + 5));
}

TEST(TraverseBvh, NearChildFirstAndPruningVisitFewLeaves) {
  const BuiltSoup s = Row();
  for (float dir : {1.0f, -1.0f}) {
    const Ray ray{{dir > 0 ? -5.0f : 1004.0f, 0.1f, 0.2f}, {dir, 0, 0}};
    int leaves = 0;
    float tmax = kInf;
    const RayTriangleSetup setup(ray);
    uint32_t best_id = kInvalidId;
    TraverseBvh(s.nodes, ray, s.Magnitude(), &tmax, [&](uint32_t first, uint32_t count) {
      ++leaves;
      for (uint32_t i = first; i < first + count; ++i) {
        float t, u, v;
        if (Intersect(setup, s.tris[s.order[i]], ray, &t, &u, &v) && t < tmax) {
          tmax = t;
          best_id = s.order[i];
        }
      }
      return false;
    });
    EXPECT_EQ(tmax, 5.0f);
    EXPECT_EQ(best_id / 2, dir > 0 ? 0u : 999u);
    // Near-first finds the first square at once; the pruned rest costs a handful of leaves
    // where a far-first or unpruned walk would open hundreds.
    EXPECT_LE(leaves, 4) << "direction " << dir;
  }
}

TEST(TraverseBvh, StopsWhenTheLeafSaysSo) {
  const BuiltSoup s = Row();
  const Ray ray{{-5, 0.1f, 0.2f}, {1, 0, 0}};
  float tmax = kInf;
  int calls = 0;
  TraverseBvh(s.nodes, ray, s.Magnitude(), &tmax, [&](uint32_t, uint32_t) {
    ++calls;
    return true;
  });
  EXPECT_EQ(calls, 1);
}

TEST(TraverseBvh, ClosedMeshThroughTheBvhIsWatertight) {
  // Rays through every vertex of a closed sphere must find a hit through the tree as well:
  // the box test may not cull boxes the triangle test would hit.
  const auto mesh =
      geometry_test::MakeClosedMesh(geometry_test::MeshShape::kSphere, 16, 1e3, 1e6);
  BuiltSoup s{mesh.triangles, {}, {}};
  s.nodes = BuildBvh(PrimitivesOf(s.tris), BvhBuildOptions{}, &s.order);
  int misses = 0;
  for (const Vec3f& v : mesh.vertices) {
    const Vec3f outside = mesh.center + (v - mesh.center) * 3.0f;
    Ray ray{outside, mesh.center - outside};
    ray.tmax = 1;
    misses += !BvhClosest(s, ray).Valid();
  }
  EXPECT_EQ(misses, 0);
}

}  // namespace
}  // namespace raystack
