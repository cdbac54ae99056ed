// The ray stack's block walk: block by block, a ray visits exactly the blocks of one
// depth-first, nearest-first walk of the octree, once each, with entries never decreasing;
// the early exit after a block agrees with the walk; tiles come out once each along a Hilbert
// curve.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <random>
#include <set>
#include <vector>

#include "render_fixture.h"
#include "common/geometry/bvh.h"
#include "slave/block_walk.h"
#include "slave/tile_source.h"

namespace raystack::testing {
namespace {

using slave::BlockWalk;

// Whether the ray may meet block b's bounds (the index's copy of its BVH root box).
bool MayHitBlock(const store::StoreReader& store, const Ray& ray, uint32_t b) {
  return store::MayHit(RayBoxSetup(ray, store.octree().magnitude()), store::BoundsOf(store.blocks()[b]),
                       ray.tmin, ray.tmax);
}

// Every block of every leaf VisitLeaves reports before `tmax` (the store's own walk) whose
// bounds the ray may meet.
std::vector<uint32_t> BlocksByVisitLeaves(const store::StoreReader& store, const Ray& ray) {
  std::vector<uint32_t> blocks;
  float bound = ray.tmax;
  const store::OctreeView octree = store.octree();
  const RayBoxSetup setup(ray, octree.magnitude());
  octree.VisitLeaves(ray, setup, &bound, [&](uint32_t, const store::OctreeNode& leaf, float, float) {
    for (uint32_t b = leaf.first; b < leaf.first + leaf.count; ++b)
      if (MayHitBlock(store, ray, b)) blocks.push_back(b);
    return true;
  });
  return blocks;
}

std::vector<uint32_t> BlocksByWalk(const BlockWalk& walk, const Ray& ray) {
  std::vector<uint32_t> blocks;
  for (uint32_t b = walk.First(ray); b != kInvalidId; b = walk.Next(ray, b)) {
    blocks.push_back(b);
    if (blocks.size() > 100000) break;  // a walk that never ends fails below
  }
  return blocks;
}

// The walk's order spelt out plainly: a recursive depth-first walk over the cells alone, each
// node's children the ray meets sorted by (entry, exit, higher child first), slab distances as
// IntersectBox has them; every block of a leaf it reaches (the caller leaves out those whose
// bounds the ray misses: the walk's pruning of whole nodes must come to the same).
void ReferenceWalk(const store::OctreeView& octree, const Ray& ray, uint32_t node,
                   const Bounds3f& cell, std::vector<uint32_t>* out) {
  const store::OctreeNode& n = octree.nodes()[node];
  if (n.kind == store::kOctreeLeaf) {
    for (uint32_t b = n.first; b < n.first + n.count; ++b) out->push_back(b);
    return;
  }
  if (n.kind != store::kOctreeInner) return;
  struct Child {
    int i;
    float enter, exit;
    Bounds3f cell;
  };
  std::vector<Child> children;
  const RayBoxSetup setup(ray, octree.magnitude());
  for (int i = 0; i < 8; ++i) {
    if (octree.nodes()[n.first + i].kind == store::kOctreeEmpty) continue;
    const Bounds3f c = store::ChildCell(cell, i);
    float enter = ray.tmin, exit = std::numeric_limits<float>::infinity();
    for (int a = 0; a < 3; ++a) {
      const float near_plane = setup.dir_is_neg[a] ? c.upper[a] : c.lower[a];
      const float far_plane = setup.dir_is_neg[a] ? c.lower[a] : c.upper[a];
      const float tn = (near_plane - setup.origin[a]) * setup.inv_dir[a] - setup.pad[a];
      const float tf =
          (far_plane - setup.origin[a]) * setup.inv_dir[a] * bvh_internal::kFarScale + setup.pad[a];
      enter = tn > enter ? tn : enter;
      exit = tf < exit ? tf : exit;
    }
    const float t1 = ray.tmax * bvh_internal::kFarScale;
    if (enter > std::min(exit, t1)) continue;
    children.push_back({i, enter, exit, c});
  }
  std::sort(children.begin(), children.end(), [](const Child& a, const Child& b) {
    return slave::VisitsBefore(a.enter, a.exit, a.i, b.enter, b.exit, b.i);
  });
  for (const Child& c : children) ReferenceWalk(octree, ray, n.first + c.i, c.cell, out);
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

// Where the ray enters and leaves a block's cell (enter >= exit: it passes only within the
// box tests' margins, past an edge or a corner).
struct CellSpan {
  float enter, exit;
};
CellSpan SpanOf(const store::BlockEntry& e, const Ray& ray) {
  CellSpan s{ray.tmin, ray.tmax};
  for (int a = 0; a < 3; ++a) {
    const float inv = 1.0f / ray.direction[a];
    const float t0 = ((inv < 0 ? e.cell_upper[a] : e.cell_lower[a]) - ray.origin[a]) * inv;
    const float t1 = ((inv < 0 ? e.cell_lower[a] : e.cell_upper[a]) - ray.origin[a]) * inv;
    s.enter = t0 > s.enter ? t0 : s.enter;
    s.exit = t1 < s.exit ? t1 : s.exit;
  }
  return s;
}

TEST(BlockWalk, VisitsEveryBlockTheRayCrossesOnceNearestFirst) {
  TestStore s = BuildGenerated("spheres:60000", 4);
  const store::OctreeView octree = s.reader->octree();
  const BlockWalk walk(octree, s.reader->blocks());
  ASSERT_GT(s.reader->blocks().size(), 50u);
  size_t visited = 0, skipped = 0;
  for (Ray ray : TestRays(*s.reader, 4000)) {
    for (const float tmax : {std::numeric_limits<float>::infinity(), 0.4f}) {
      ray.tmax = tmax;
      const std::vector<uint32_t> walked = BlocksByWalk(walk, ray);
      std::vector<uint32_t> crossed, reference;
      ReferenceWalk(octree, ray, 0, octree.root_cell(), &crossed);
      for (uint32_t b : crossed) {
        if (MayHitBlock(*s.reader, ray, b)) reference.push_back(b);
        else ++skipped;
      }
      ASSERT_EQ(walked, reference);
      // Nearest first: the entries of the cells the ray passes through never decrease. (A
      // cell it only grazes within the margins, at an edge it passes within ulps of, may come
      // before a neighbour it enters a hair earlier: the walk orders children by the ray's
      // direction, exact only for the cells the ray truly crosses.)
      float last_entry = -std::numeric_limits<float>::infinity();
      for (const uint32_t b : walked) {
        const CellSpan span = SpanOf(s.reader->blocks()[b], ray);
        if (!(span.enter < span.exit)) continue;
        ASSERT_LE(last_entry, span.enter);
        last_entry = span.enter;
      }
      // The same blocks as the store's own front-to-back walk (which orders ties otherwise).
      std::vector<uint32_t> sorted = walked, expected = BlocksByVisitLeaves(*s.reader, ray);
      std::sort(sorted.begin(), sorted.end());
      std::sort(expected.begin(), expected.end());
      ASSERT_EQ(sorted, expected);
      visited += walked.size();
    }
  }
  EXPECT_GT(visited, 4000u);  // the rays do cross the model
  EXPECT_GT(skipped, visited / 10);  // and their cells hold blocks they miss
}

// Rays that start inside the octree take a short cut to their first cell (point location);
// starts on a cell's faces, a few ulps either side of them, leaving a block whose bounds reach
// the face, and later than the origin (tmin) are where it could go wrong: the walk must still
// be the reference one, block for block.
TEST(BlockWalk, RaysStartingOnAndNearCellFacesWalkAsFromTheRoot) {
  TestStore s = BuildGenerated("spheres:60000", 4);
  const store::OctreeView octree = s.reader->octree();
  const BlockWalk walk(octree, s.reader->blocks());
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0, 1);
  const auto& blocks = s.reader->blocks();
  size_t visited = 0;
  for (int i = 0; i < 6000; ++i) {
    const store::BlockEntry& e = blocks[rng() % blocks.size()];
    // Half the rays start within the block's bounds and leave it through a face of its cell:
    // the walk must visit this block (met at its start) before the cell beyond the face.
    const bool leaving = i % 2 == 0;
    Ray ray;
    for (int a = 0; a < 3; ++a) {
      const float lo = leaving ? e.bounds_lower[a] : e.cell_lower[a];
      const float hi = leaving ? e.bounds_upper[a] : e.cell_upper[a];
      ray.origin[a] = lo + u(rng) * (hi - lo);
    }
    // Onto a face of the cell (or a corner), then nudged by a few ulps either way.
    const int axis = (i / 2) % 3;
    const bool upper = (i & 8) != 0;
    float& x = ray.origin[axis];
    x = upper ? e.cell_upper[axis] : e.cell_lower[axis];
    for (int k = static_cast<int>(rng() % 9) - 4; k != 0; k += k > 0 ? -1 : 1)
      x = std::nextafter(x, k > 0 ? std::numeric_limits<float>::infinity()
                                  : -std::numeric_limits<float>::infinity());
    if (i % 7 == 0) ray.origin[(axis + 1) % 3] = e.cell_upper[(axis + 1) % 3];
    Vec3f d{u(rng) * 2 - 1, u(rng) * 2 - 1, u(rng) * 2 - 1};
    if (leaving) d[axis] = (upper ? 1.0f : -1.0f) * (0.05f + u(rng));
    if (i % 5 == 0) d[axis] = 0;  // along the face
    ray.direction = Normalize(d);
    ray.tmin = ((i / 4) % 3 == 1) ? u(rng) * 0.05f : 0.0f;
    ray.tmax = (i % 2) ? std::numeric_limits<float>::infinity() : 0.1f + u(rng);
    const std::vector<uint32_t> walked = BlocksByWalk(walk, ray);
    std::vector<uint32_t> crossed, reference;
    ReferenceWalk(octree, ray, 0, octree.root_cell(), &crossed);
    for (uint32_t b : crossed)
      if (MayHitBlock(*s.reader, ray, b)) reference.push_back(b);
    ASSERT_EQ(walked, reference) << "ray " << i;
    visited += walked.size();
  }
  EXPECT_GT(visited, 6000u);
}

// A block the walk leaves out (its bounds missed) is one whose triangles the ray does not hit:
// for every block of the crossed cells, MayHit false implies no hit from the block itself.
TEST(BlockWalk, ABlockLeftOutIsOneTheRayDoesNotHit) {
  TestStore s = BuildGenerated("spheres:60000", 4);
  const store::OctreeView octree = s.reader->octree();
  std::vector<uint8_t> stored;
  store::AlignedBuffer scratch;
  std::vector<store::AlignedBuffer> raws(s.reader->blocks().size());
  std::vector<store::BlockView> views(raws.size());
  for (uint32_t b = 0; b < raws.size(); ++b) {
    Expected<store::BlockView> v = s.reader->Load(b, &stored, &scratch, &raws[b]);
    ASSERT_TRUE(v.ok()) << v.status().message();
    views[b] = *v;
  }
  size_t left_out = 0;
  for (Ray ray : TestRays(*s.reader, 2000)) {
    ray.tmax = std::numeric_limits<float>::infinity();
    std::vector<uint32_t> crossed;
    ReferenceWalk(octree, ray, 0, octree.root_cell(), &crossed);
    for (uint32_t b : crossed) {
      if (MayHitBlock(*s.reader, ray, b)) continue;
      ++left_out;
      Hit hit;
      hit.t = ray.tmax;
      ASSERT_FALSE(views[b].Intersect(ray, &hit)) << "block " << b;
      ASSERT_FALSE(views[b].Occluded(ray)) << "block " << b;
    }
  }
  EXPECT_GT(left_out, 1000u);
}

TEST(BlockWalk, ARayWhoseHitShrinksStopsAtTheSameBlockAsOneThatKnewIt) {
  TestStore s = BuildGenerated("spheres:60000", 4);
  const BlockWalk walk(s.reader->octree(), s.reader->blocks());
  std::mt19937 rng(3);
  int stopped_early = 0;
  for (Ray ray : TestRays(*s.reader, 3000)) {
    const float hit = std::uniform_real_distribution<float>(0.01f, 4.0f)(rng);
    Ray knowing = ray;
    knowing.tmax = hit;
    const std::vector<uint32_t> expected = BlocksByWalk(walk, knowing);
    // The ray finds its hit in its first block; the rest of its walk uses it.
    std::vector<uint32_t> got;
    for (uint32_t b = walk.First(ray); b != kInvalidId; b = walk.Next(ray, b)) {
      got.push_back(b);
      ray.tmax = hit;
    }
    if (!got.empty() && expected.size() < BlocksByWalk(walk, Ray{ray.origin, ray.direction}).size())
      ++stopped_early;
    if (!expected.empty()) {
      EXPECT_EQ(got, expected);
    }
  }
  EXPECT_GT(stopped_early, 100);
}

TEST(BlockWalk, DoneAfterOnlyWhenTheWalkHasNothingMore) {
  TestStore s = BuildGenerated("spheres:60000", 4);
  const BlockWalk walk(s.reader->octree(), s.reader->blocks());
  std::mt19937 rng(5);
  int done = 0;
  for (Ray ray : TestRays(*s.reader, 3000)) {
    ray.tmax = std::uniform_real_distribution<float>(0.01f, 4.0f)(rng);
    for (uint32_t b = walk.First(ray); b != kInvalidId; b = walk.Next(ray, b)) {
      if (walk.DoneAfter(ray, b)) {
        ++done;
        EXPECT_EQ(walk.Next(ray, b), kInvalidId);
      }
    }
  }
  EXPECT_GT(done, 100);
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
