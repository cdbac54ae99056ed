// The ray stack's block walk: a ray resumed from its (t, skip) point visits exactly the blocks
// an uninterrupted front-to-back walk of the octree visits, once each, nearest first; the
// early exit after a block agrees with the walk; tiles come out once each along a Hilbert
// curve.

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <limits>
#include <random>
#include <set>
#include <vector>

#include "render_fixture.h"
#include "slave/block_walk.h"
#include "slave/tile_source.h"

namespace raystack::testing {
namespace {

using slave::BlockCell;
using slave::FindNextBlock;
using slave::NextBlock;

// Every block of every leaf VisitLeaves reports, front to back, before `tmax`.
std::vector<uint32_t> BlocksByVisitLeaves(const store::OctreeView& octree, const Ray& ray,
                                          float tmax) {
  std::vector<uint32_t> blocks;
  float bound = tmax;
  octree.VisitLeaves(ray, &bound, [&](uint32_t, const store::OctreeNode& leaf, float, float) {
    for (uint32_t b = leaf.first; b < leaf.first + leaf.count; ++b) blocks.push_back(b);
    return true;
  });
  return blocks;
}

std::vector<uint32_t> BlocksByResumedWalk(const store::OctreeView& octree, const Ray& ray,
                                          float tmax) {
  std::vector<uint32_t> blocks;
  float resume_t = -std::numeric_limits<float>::infinity();
  uint32_t skip = 0;
  for (;;) {
    const NextBlock next = FindNextBlock(octree, ray, tmax, resume_t, skip);
    if (next.block == kInvalidId) break;
    blocks.push_back(next.block);
    resume_t = next.resume_t;
    skip = next.skip;
    if (blocks.size() > 100000) break;  // a walk that never ends fails below
  }
  return blocks;
}

// Rays from outside and from inside the model, in every direction, some axis-parallel and
// some through the cells' shared planes (the root cell's centre), where ties are common.
std::vector<Ray> TestRays(const store::StoreReader& store, int count) {
  const Bounds3f b = store.model_bounds();
  const Bounds3f root = store.octree().root_cell();
  const Vec3f centre = (root.lower + root.upper) * 0.5f;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0, 1);
  std::vector<Ray> rays;
  for (int i = 0; i < count; ++i) {
    Ray r;
    const Vec3f inside{b.lower.x + u(rng) * (b.upper.x - b.lower.x),
                       b.lower.y + u(rng) * (b.upper.y - b.lower.y),
                       b.lower.z + u(rng) * (b.upper.z - b.lower.z)};
    Vec3f d{u(rng) * 2 - 1, u(rng) * 2 - 1, u(rng) * 2 - 1};
    switch (i % 4) {
      case 0: r.origin = inside; break;
      case 1: r.origin = inside + Normalize(d) * (-3.0f * Length(b.upper - b.lower)); break;
      case 2:  // axis-parallel through the model
        r.origin = inside;
        d = Vec3f{0, 0, 0};
        d[i % 3] = (i & 8) ? 1.0f : -1.0f;
        break;
      case 3:  // through the centre of the root cell: every level's mid planes
        r.origin = inside;
        d = centre - inside;
        break;
    }
    r.direction = Normalize(d);
    r.tmin = 0;
    rays.push_back(r);
  }
  return rays;
}

// Entry distance of a block's cell along the ray (slab test, as the walk computes it).
float CellEntry(const store::BlockEntry& e, const Ray& ray) {
  float enter = ray.tmin;
  for (int a = 0; a < 3; ++a) {
    const float inv = 1.0f / ray.direction[a];
    const float t = ((inv < 0 ? e.cell_upper[a] : e.cell_lower[a]) - ray.origin[a]) * inv;
    enter = t > enter ? t : enter;
  }
  return enter;
}

TEST(BlockWalk, ResumedWalkVisitsTheBlocksOfOneFrontToBackWalk) {
  TestStore s = BuildGenerated("spheres:60000", 4);
  const store::OctreeView octree = s.reader->octree();
  ASSERT_GT(s.reader->blocks().size(), 50u);
  size_t visited = 0;
  for (const Ray& ray : TestRays(*s.reader, 4000)) {
    for (const float tmax : {std::numeric_limits<float>::infinity(), 0.4f}) {
      std::vector<uint32_t> expected = BlocksByVisitLeaves(octree, ray, tmax);
      const std::vector<uint32_t> walked = BlocksByResumedWalk(octree, ray, tmax);
      // Nearest first: entries never decrease (the store's walk may order ties otherwise).
      for (size_t i = 1; i < walked.size(); ++i)
        ASSERT_LE(CellEntry(s.reader->blocks()[walked[i - 1]], ray),
                  CellEntry(s.reader->blocks()[walked[i]], ray));
      std::vector<uint32_t> sorted = walked;
      std::sort(sorted.begin(), sorted.end());
      std::sort(expected.begin(), expected.end());
      ASSERT_EQ(sorted, expected);  // every block once (no block twice, none lost)
      visited += expected.size();
    }
  }
  EXPECT_GT(visited, 4000u);  // the rays do cross the model
}

TEST(BlockWalk, EarlyExitOnlyWhenTheWalkFindsNothingMore) {
  TestStore s = BuildGenerated("spheres:60000", 4);
  const store::OctreeView octree = s.reader->octree();
  const std::vector<BlockCell> cells = slave::BlockCells(octree, s.reader->blocks().size());
  std::mt19937 rng(3);
  int early = 0;
  for (Ray ray : TestRays(*s.reader, 3000)) {
    const std::vector<uint32_t> blocks = BlocksByResumedWalk(octree, ray, ray.tmax);
    if (blocks.empty()) continue;
    // Pretend a hit somewhere along the ray, then ask after each block.
    float resume_t = -std::numeric_limits<float>::infinity();
    uint32_t skip = 0;
    ray.tmax = std::uniform_real_distribution<float>(0.01f, 4.0f)(rng);
    for (;;) {
      const NextBlock next = FindNextBlock(octree, ray, ray.tmax, resume_t, skip);
      if (next.block == kInvalidId) break;
      resume_t = next.resume_t;
      skip = next.skip;
      if (slave::DoneAfterBlock(cells, ray, next.block)) {
        ++early;
        EXPECT_EQ(FindNextBlock(octree, ray, ray.tmax, resume_t, skip).block, kInvalidId);
        break;
      }
    }
  }
  EXPECT_GT(early, 100);
}

TEST(BlockWalk, BlockCellsHoldEachBlocksLeafCell) {
  TestStore s = BuildGenerated("spheres:20000", 4);
  const std::vector<BlockCell> cells =
      slave::BlockCells(s.reader->octree(), s.reader->blocks().size());
  for (uint32_t b = 0; b < s.reader->blocks().size(); ++b) {
    const BlockCell& c = cells[b];
    const store::BlockEntry& e = s.reader->blocks()[b];
    for (int a = 0; a < 3; ++a) {  // the converter's cells, bit for bit
      EXPECT_EQ(c.lower[a], e.cell_lower[a]) << "block " << b;
      EXPECT_EQ(c.upper[a], e.cell_upper[a]) << "block " << b;
    }
    const store::OctreeNode& leaf = s.reader->octree().nodes()[e.octree_leaf];
    EXPECT_EQ(c.last_in_leaf, b + 1 == leaf.first + leaf.count) << "block " << b;
  }
}

TEST(GridTileSource, HandsOutEveryTileOnceNeighboursInTurn) {
  for (const auto& [w, h, size] : {std::tuple{640, 480, 32}, std::tuple{100, 37, 16},
                                   std::tuple{1, 1, 32}, std::tuple{256, 256, 32}}) {
    slave::GridTileSource source(w, h, size);
    std::set<std::pair<int, int>> seen;
    slave::Tile t, previous;
    int pixels = 0, far_steps = 0, n = 0;
    while (source.Next(0, &t)) {
      EXPECT_TRUE(seen.insert({t.x0, t.y0}).second) << "tile handed out twice";
      EXPECT_EQ(t.x0 % size, 0);
      EXPECT_EQ(t.y0 % size, 0);
      EXPECT_LE(t.x1, w);
      EXPECT_LE(t.y1, h);
      pixels += t.pixels();
      if (n++ > 0 && std::abs(t.x0 - previous.x0) + std::abs(t.y0 - previous.y0) != size)
        ++far_steps;
      previous = t;
    }
    EXPECT_EQ(pixels, w * h);
    // On a power-of-two grid a Hilbert curve only steps to a neighbour; cropped grids jump
    // over the cut-off part now and then.
    if (w == 256) {
      EXPECT_EQ(far_steps, 0);
    }
    EXPECT_LT(far_steps, n / 3 + 1);
  }
}

}  // namespace
}  // namespace raystack::testing
