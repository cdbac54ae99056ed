// IntersectBatch and OccludedBatch must equal, bit for bit, one call of Intersect or
// Occluded per ray: the renderer traces block queues in batches and its images are compared
// bit for bit against the single-ray path and brute force.

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "common/store/block_codec.h"
#include "common/store/block_encoder.h"
#include "common/store/block_view.h"
#include "tools/prep/clip.h"

namespace raystack::store {
namespace {

// A block of n small random triangles in the unit cell, plus `duplicates` coplanar copies of
// the first ones under other ids (distance ties broken by id).
class Block {
 public:
  Block(int n, int duplicates, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(0.02f, 0.98f), s(-0.08f, 0.08f);
    std::vector<PackedTriangle> tris;
    std::vector<uint32_t> refs;
    std::vector<Bounds3f> bounds;
    const Bounds3f cell{{0, 0, 0}, {1, 1, 1}};
    for (int i = 0; i < n + duplicates; ++i) {
      PackedTriangle t{};
      if (i < n) {
        const Vec3f a{u(rng), u(rng), u(rng)};
        t.p[0] = a;
        t.p[1] = a + Vec3f{s(rng), s(rng), s(rng)};
        t.p[2] = a + Vec3f{s(rng), s(rng), s(rng)};
      } else {
        t.p[0] = tris[static_cast<size_t>(i - n)].p[0];
        t.p[1] = tris[static_cast<size_t>(i - n)].p[1];
        t.p[2] = tris[static_cast<size_t>(i - n)].p[2];
      }
      t.id = static_cast<uint32_t>(7919 * i % 100003);  // ids not in BVH order
      tris.push_back(t);
      refs.push_back(static_cast<uint32_t>(i));
      bounds.push_back(prep::ClipTriangleToCell(t.p, cell));
    }
    EncodeInput in;
    in.triangles = tris;
    in.refs = refs;
    in.ref_bounds = bounds;
    in.cell = cell;
    std::vector<uint8_t> raw;
    BlockEncoder().Encode(in, &raw);
    buffer_.Reserve(raw.size());
    std::memcpy(buffer_.data(), raw.data(), raw.size());
    Expected<BlockView> v = BlockView::Parse(buffer_.data(), raw.size(), 5);
    EXPECT_TRUE(v.ok());
    if (v.ok()) view_ = *v;
  }
  const BlockView& view() const { return view_; }

 private:
  AlignedBuffer buffer_;
  BlockView view_;
};

bool SameHit(const Hit& a, const Hit& b) { return std::memcmp(&a, &b, sizeof(Hit)) == 0; }

// Checks both batch forms against the single-ray forms, starting from `start` hits.
void ExpectBatchEqualsSingle(const BlockView& block, const std::vector<Ray>& rays,
                             const std::vector<Hit>& start) {
  std::vector<Hit> single = start, batch = start;
  std::vector<uint8_t> single_occluded(rays.size()), batch_occluded(rays.size(), 7);
  for (size_t i = 0; i < rays.size(); ++i) {
    block.Intersect(rays[i], &single[i]);
    single_occluded[i] = block.Occluded(rays[i]) ? 1 : 0;
  }
  block.IntersectBatch(rays, batch);
  block.OccludedBatch(rays, batch_occluded);
  size_t hits = 0, occluded = 0;
  for (size_t i = 0; i < rays.size(); ++i) {
    ASSERT_TRUE(SameHit(single[i], batch[i]))
        << "ray " << i << ": t " << single[i].t << " vs " << batch[i].t << ", id "
        << single[i].triangle_id << " vs " << batch[i].triangle_id;
    ASSERT_EQ(single_occluded[i], batch_occluded[i]) << "ray " << i;
    hits += single[i].Valid();
    occluded += single_occluded[i];
  }
  // The rays must exercise both outcomes, or the comparison proves little.
  if (rays.size() >= 100) {
    EXPECT_GT(hits, 0u);
    EXPECT_LT(hits, rays.size());
    EXPECT_GT(occluded, 0u);
  }
}

std::vector<Hit> NoHits(size_t n) { return std::vector<Hit>(n); }

TEST(BlockViewBatch, RandomRaysFromInsideAndOutside) {
  const Block b(2000, 50, 1);
  std::mt19937 rng(2);
  std::uniform_real_distribution<float> u(-0.5f, 1.5f), d(-1, 1);
  std::vector<Ray> rays(1001);  // not a multiple of 4, more than one 256-ray chunk
  for (Ray& r : rays) {
    r.origin = {u(rng), u(rng), u(rng)};
    r.direction = {d(rng), d(rng), d(rng)};
  }
  ExpectBatchEqualsSingle(b.view(), rays, NoHits(rays.size()));
}

TEST(BlockViewBatch, CoherentPinholeRays) {
  const Block b(3000, 100, 3);
  std::vector<Ray> rays;
  for (int j = 0; j < 40; ++j) {
    for (int i = 0; i < 40; ++i) {
      rays.push_back(Ray{{0.5f, 0.5f, -1.0f},
                         {(static_cast<float>(i) - 19.5f) / 50, (static_cast<float>(j) - 19.5f) / 50, 1}});
    }
  }
  ExpectBatchEqualsSingle(b.view(), rays, NoHits(rays.size()));
}

TEST(BlockViewBatch, TminTmaxAndHitsFromEarlierBlocks) {
  const Block b(2000, 0, 4);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0, 1), d(-1, 1), t(0, 0.6f);
  std::vector<Ray> rays(700);
  std::vector<Hit> start(rays.size());
  for (size_t i = 0; i < rays.size(); ++i) {
    rays[i].origin = {u(rng), u(rng), u(rng)};  // inside the block
    rays[i].direction = {d(rng), d(rng), d(rng)};
    rays[i].tmin = i % 3 == 0 ? 0.0f : t(rng);
    rays[i].tmax = i % 5 == 0 ? std::numeric_limits<float>::infinity() : 0.3f + t(rng);
    if (i % 4 == 1) {  // a hit found in an earlier block, which this block must beat
      start[i].t = 0.2f + t(rng);
      start[i].triangle_id = 50000;
      start[i].block_id = 1;
      start[i].local_triangle = 3;
    }
    if (!start[i].Valid()) start[i].t = rays[i].tmax;
  }
  ExpectBatchEqualsSingle(b.view(), rays, start);
}

TEST(BlockViewBatch, DirectionsWithZeroComponents) {
  const Block b(2000, 20, 6);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-0.2f, 1.2f), d(-1, 1);
  std::vector<Ray> rays;
  for (int i = 0; i < 1200; ++i) {
    Ray r;
    r.origin = {u(rng), u(rng), u(rng)};
    r.direction = {d(rng), d(rng), d(rng)};
    // One or two components zero, of either sign (the sign picks the octant).
    const int pattern = i % 12;
    for (int a = 0; a < 3; ++a) {
      if (pattern & (1 << a)) r.direction[a] = (pattern & 8) ? -0.0f : 0.0f;
    }
    if (r.direction.x == 0 && r.direction.y == 0 && r.direction.z == 0) r.direction.z = 1;
    rays.push_back(r);
  }
  ExpectBatchEqualsSingle(b.view(), rays, NoHits(rays.size()));
}

TEST(BlockViewBatch, SmallAndEmptyBatches) {
  const Block b(500, 0, 8);
  for (size_t n : {0, 1, 2, 3, 4, 5}) {
    std::vector<Ray> rays;
    for (size_t i = 0; i < n; ++i)
      rays.push_back(Ray{{0.5f, 0.5f, -1}, {0.01f * static_cast<float>(i), 0.02f, 1}});
    ExpectBatchEqualsSingle(b.view(), rays, NoHits(n));
  }
}

}  // namespace
}  // namespace raystack::store
