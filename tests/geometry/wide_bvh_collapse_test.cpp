#include "common/geometry/wide_bvh_collapse.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <limits>
#include <random>
#include <vector>

#include "common/geometry/bvh.h"

namespace raystack {
namespace {

constexpr float kNodeCost = 1.0f, kPrimitiveCost = 0.25f;
constexpr float kInf = std::numeric_limits<float>::infinity();

float Area(const BvhNode& n) {
  const float x = n.upper[0] - n.lower[0], y = n.upper[1] - n.lower[1], z = n.upper[2] - n.lower[2];
  return x * y + y * z + z * x;
}

// The binary tree over n random boxes, some clustered and some large, as BuildBvh makes it.
std::vector<BvhNode> RandomTree(int n, int max_leaf, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> pos(0, 1), size(0.001f, 0.2f);
  std::vector<BvhBuildPrimitive> prims(static_cast<size_t>(n));
  for (BvhBuildPrimitive& p : prims) {
    const Vec3f c{pos(rng), pos(rng) * 0.2f, pos(rng)};
    const float s = size(rng) * size(rng) * 5;
    p.bounds.Extend(c);
    p.bounds.Extend(c + Vec3f{s, s * 0.5f, s * 2});
  }
  BvhBuildOptions options;
  options.max_leaf_size = max_leaf;
  options.intersection_cost = kPrimitiveCost;
  std::vector<uint32_t> order;
  return BuildBvh(prims, options, &order);
}

// Checks the plan of `root`'s subtree from wide node `n` down: 2 .. width children a node,
// leaves of at most kMaxLeaf primitives covering the subtree's run once each, in order. Returns
// the SAH cost of the wide subtree as it is built.
float CheckedCost(const std::vector<BvhNode>& tree, const WideCollapse& plan, uint32_t n, int width,
                  uint32_t* next_primitive) {
  uint32_t children[WideCollapse::kMaxWidth];
  const int count = plan.Children(n, children);
  EXPECT_GE(count, 2);
  EXPECT_LE(count, width);
  float cost = Area(tree[n]) * kNodeCost;
  for (int k = 0; k < count; ++k) {
    const uint32_t c = children[k];
    if (plan.AsLeaf(c)) {
      EXPECT_LE(plan.Count(c), static_cast<uint32_t>(WideCollapse::kMaxLeaf));
      EXPECT_EQ(plan.First(c), *next_primitive);
      *next_primitive += plan.Count(c);
      cost += Area(tree[c]) * kPrimitiveCost * static_cast<float>(plan.Count(c));
    } else {
      EXPECT_EQ(tree[c].count, 0);
      cost += CheckedCost(tree, plan, c, width, next_primitive);
    }
  }
  return cost;
}

uint32_t Primitives(const std::vector<BvhNode>& tree, uint32_t n) {
  return tree[n].count != 0 ? tree[n].count : Primitives(tree, n + 1) + Primitives(tree, tree[n].offset);
}

// The greedy collapse (the largest inner child opened until the node is full, binary leaves as
// leaves): a valid plan the optimal one must not be worse than.
float GreedyCost(const std::vector<BvhNode>& tree, uint32_t n, int width) {
  std::vector<uint32_t> children{n + 1, tree[n].offset};
  while (static_cast<int>(children.size()) < width) {
    auto best = children.end();
    for (auto it = children.begin(); it != children.end(); ++it)
      if (tree[*it].count == 0 && (best == children.end() || Area(tree[*it]) > Area(tree[*best]))) best = it;
    if (best == children.end()) break;
    const uint32_t open = *best;
    *best = open + 1;
    children.push_back(tree[open].offset);
  }
  float cost = Area(tree[n]) * kNodeCost;
  for (uint32_t c : children)
    cost += tree[c].count != 0 ? Area(tree[c]) * kPrimitiveCost * static_cast<float>(tree[c].count)
                               : GreedyCost(tree, c, width);
  return cost;
}

// Every collapse, enumerated: the least cost of n as one child, and of n as a wide node over
// each possible set of at most `width` descendants.
float BruteAsChild(const std::vector<BvhNode>& tree, uint32_t n, int width);
// The sets of at most `width` nodes that can stand for n's subtree side by side, with their costs.
std::vector<std::pair<int, float>> BruteFrontiers(const std::vector<BvhNode>& tree, uint32_t n, int width) {
  std::vector<std::pair<int, float>> out{{1, BruteAsChild(tree, n, width)}};
  if (tree[n].count != 0) return out;
  for (const auto& [a, ca] : BruteFrontiers(tree, n + 1, width))
    for (const auto& [b, cb] : BruteFrontiers(tree, tree[n].offset, width))
      if (a + b <= width) out.push_back({a + b, ca + cb});
  return out;
}
float BruteAsNode(const std::vector<BvhNode>& tree, uint32_t n, int width) {
  float best = kInf;
  for (const auto& [a, ca] : BruteFrontiers(tree, n + 1, width))
    for (const auto& [b, cb] : BruteFrontiers(tree, tree[n].offset, width))
      if (a + b <= width) best = std::min(best, ca + cb);
  return Area(tree[n]) * kNodeCost + best;
}
float BruteAsChild(const std::vector<BvhNode>& tree, uint32_t n, int width) {
  const uint32_t count = Primitives(tree, n);
  const float leaf = count <= static_cast<uint32_t>(WideCollapse::kMaxLeaf)
                         ? Area(tree[n]) * kPrimitiveCost * static_cast<float>(count)
                         : kInf;
  return tree[n].count != 0 ? leaf : std::min(leaf, BruteAsNode(tree, n, width));
}

TEST(WideCollapse, PlansValidTreesNoWorseThanTheGreedyCollapse) {
  int better = 0;
  for (uint32_t seed = 1; seed <= 20; ++seed) {
    for (int max_leaf : {1, 2, 4}) {
      const std::vector<BvhNode> tree = RandomTree(200 + 37 * static_cast<int>(seed), max_leaf, seed);
      ASSERT_EQ(tree[0].count, 0);
      for (int width : {2, 4, 8}) {
        WideCollapse plan;
        plan.Plan(tree, 0, width, kNodeCost, kPrimitiveCost);
        uint32_t next = 0;
        const float built = CheckedCost(tree, plan, 0, width, &next);
        EXPECT_EQ(next, Primitives(tree, 0));  // every primitive in exactly one leaf
        EXPECT_NEAR(built, plan.Cost(), 1e-4f * built);
        const float greedy = GreedyCost(tree, 0, width);
        EXPECT_LE(plan.Cost(), greedy * (1 + 1e-5f)) << "seed " << seed << " width " << width;
        better += plan.Cost() < greedy * (1 - 1e-3f);
      }
    }
  }
  EXPECT_GT(better, 100);  // and the plan is better most of the time, not merely as good
}

TEST(WideCollapse, FindsTheLeastCostOfEveryCollapse) {
  for (uint32_t seed = 1; seed <= 30; ++seed) {
    const std::vector<BvhNode> tree = RandomTree(6 + static_cast<int>(seed % 10), 1 + seed % 3, seed);
    if (tree[0].count != 0) continue;
    for (int width : {2, 3, 4, 8}) {
      WideCollapse plan;
      plan.Plan(tree, 0, width, kNodeCost, kPrimitiveCost);
      const float brute = BruteAsNode(tree, 0, width);
      EXPECT_NEAR(plan.Cost(), brute, 1e-5f * brute) << "seed " << seed << " width " << width;
    }
  }
}

// Boxes across the whole float range have infinite areas, and flat ones NaN areas (inf x 0):
// every cost compares false, and the plan must still be a valid tree.
TEST(WideCollapse, PlansValidTreesWhenAreasOverflow) {
  std::vector<BvhBuildPrimitive> prims(300);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> coordinate(-3e38, 3e38);  // (a float range would overflow)
  auto pos = [&] { return static_cast<float>(coordinate(rng)); };
  for (size_t i = 0; i < prims.size(); ++i) {
    const Vec3f a{pos(), pos(), i % 2 ? 0.0f : pos()}, b{pos(), pos(), 0.0f};
    prims[i].bounds.Extend(a);
    prims[i].bounds.Extend(b);
  }
  BvhBuildOptions options;
  std::vector<uint32_t> order;
  const std::vector<BvhNode> tree = BuildBvh(prims, options, &order);
  ASSERT_EQ(tree[0].count, 0);
  for (int width : {2, 8}) {
    WideCollapse plan;
    plan.Plan(tree, 0, width, kNodeCost, kPrimitiveCost);
    uint32_t next = 0;
    CheckedCost(tree, plan, 0, width, &next);
    EXPECT_EQ(next, 300u);
  }
}

TEST(WideCollapse, PlansASubtreeOnItsOwn) {
  const std::vector<BvhNode> tree = RandomTree(500, 4, 3);
  const uint32_t sub = tree[0].offset;  // the root's second child
  ASSERT_EQ(tree[sub].count, 0);
  WideCollapse plan;
  plan.Plan(tree, sub, 8, kNodeCost, kPrimitiveCost);
  uint32_t next = plan.First(sub);
  const float built = CheckedCost(tree, plan, sub, 8, &next);
  EXPECT_EQ(next - plan.First(sub), Primitives(tree, sub));
  EXPECT_NEAR(built, plan.Cost(), 1e-4f * built);
  EXPECT_LE(plan.Cost(), GreedyCost(tree, sub, 8) * (1 + 1e-5f));
}

}  // namespace
}  // namespace raystack
