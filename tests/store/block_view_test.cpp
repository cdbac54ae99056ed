// BlockView::Parse is the last line of defence: a block whose checksum is right but whose
// content is hostile must be refused, never traversed out of bounds.

#include "common/store/block_view.h"

#include <gtest/gtest.h>

#include <sys/mman.h>

#include <cstring>
#include <functional>
#include <memory>
#include <limits>
#include <random>

#include "common/store/block_codec.h"
#include "common/store/block_layout.h"
#include "common/store/block_encoder.h"
#include "tools/prep/clip.h"

namespace raystack::store {
namespace {

// Encodes the triangles `refs` names (their clipped bounds beside them) as one block of `cell`;
// returns its vertex count.
uint32_t EncodeBlock(std::span<const PackedTriangle> tris, std::span<const uint32_t> refs,
                     std::span<const Bounds3f> bounds, const Bounds3f& cell, std::vector<uint8_t>* raw) {
  EncodeInput in;
  in.triangles = tris;
  in.refs = refs;
  in.ref_bounds = bounds;
  in.cell = cell;
  BlockEncoder encoder;
  return encoder.Encode(in, raw);
}

struct Fixture {
  std::vector<PackedTriangle> tris;
  std::vector<uint32_t> refs;
  std::vector<Bounds3f> bounds;
  std::vector<uint8_t> raw;
  Bounds3f cell{{0, 0, 0}, {1, 1, 1}};

  explicit Fixture(int n) {
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> u(0.05f, 0.95f);
    for (int i = 0; i < n; ++i) {
      PackedTriangle t{};
      const Vec3f a{u(rng), u(rng), u(rng)};
      t.p[0] = a;
      t.p[1] = a + Vec3f{0.05f, 0.01f, 0};
      t.p[2] = a + Vec3f{0, 0.05f, 0.02f};
      t.id = static_cast<uint32_t>(1000 + i);
      t.material_and_flags = static_cast<uint32_t>(i % 3);
      tris.push_back(t);
      refs.push_back(static_cast<uint32_t>(i));
      bounds.push_back(prep::ClipTriangleToCell(t.p, cell));
    }
    EncodeBlock(tris, refs, bounds, cell, &raw);
  }
};

Expected<BlockView> ParseCopy(const std::vector<uint8_t>& raw, AlignedBuffer* buffer, uint32_t id) {
  buffer->Reserve(raw.size());
  std::memcpy(buffer->data(), raw.data(), raw.size());
  return BlockView::Parse(buffer->data(), raw.size(), id);
}

TEST(BlockView, EncodedBlockParsesAndKeepsEveryTriangle) {
  Fixture f(500);
  AlignedBuffer buffer;
  Expected<BlockView> v = ParseCopy(f.raw, &buffer, 9);
  ASSERT_TRUE(v.ok()) << v.status().message();
  EXPECT_EQ(v->triangle_count(), 500u);
  EXPECT_LT(v->vertex_count(), 1500u + 1);
  std::vector<int> seen(500, 0);
  for (uint32_t t = 0; t < v->triangle_count(); ++t) {
    const uint32_t i = v->TriangleId(t) - 1000;
    ASSERT_LT(i, 500u);
    ++seen[i];
    Vec3f p0, p1, p2;
    v->TriangleVertices(t, &p0, &p1, &p2);
    EXPECT_TRUE(p0 == f.tris[i].p[0] && p1 == f.tris[i].p[1] && p2 == f.tris[i].p[2]);
    EXPECT_EQ(v->Material(t), i % 3);
  }
  for (int s : seen) EXPECT_EQ(s, 1);
  EXPECT_FALSE(v->has_normals());  // the source had none: none stored
  EXPECT_FALSE(v->has_uvs());
}

// Found by a scale review: the encoder named a vertex's source as `tri * 3 + corner` in 32 bits,
// where `tri` indexes the converter's whole bucket (up to --mem-limit / 640 triangles: more than
// 2^32 / 3 from ~850 GB on). Past 1,431,655,765 the name wrapped to another triangle: the block
// took that one's corners, silently. Two triangles that far into a sparse mapping (66 GB of
// address space, a few pages touched) must keep their own corners and share their edge.
TEST(BlockEncoder, TrianglesPastTheFirstBillionAndAHalfKeepTheirOwnCorners) {
  constexpr size_t kFar = 1'500'000'000;
  const size_t bytes = (kFar + 2) * sizeof(PackedTriangle);
  void* mapped = mmap(nullptr, bytes, PROT_READ | PROT_WRITE,
                      MAP_PRIVATE | MAP_ANONYMOUS | MAP_NORESERVE, -1, 0);
  if (mapped == MAP_FAILED)
    GTEST_SKIP() << "cannot map " << bytes << " bytes of address space (ulimit -v or strict overcommit)";
  const std::unique_ptr<void, std::function<void(void*)>> unmap(
      mapped, [bytes](void* p) { munmap(p, bytes); });  // also when an assertion returns early
  const std::span<PackedTriangle> tris(static_cast<PackedTriangle*>(mapped), kFar + 2);
  const Vec3f a{0.2f, 0.2f, 0.5f}, b{0.8f, 0.2f, 0.5f}, c{0.8f, 0.8f, 0.5f}, d{0.2f, 0.8f, 0.5f};
  tris[kFar] = {{a, b, c}, 7, kNoMaterial};
  tris[kFar + 1] = {{a, c, d}, 8, kNoMaterial};
  const Bounds3f cell{{0, 0, 0}, {1, 1, 1}};
  const std::vector<uint32_t> refs = {kFar, kFar + 1};
  const std::vector<Bounds3f> bounds = {prep::ClipTriangleToCell(tris[kFar].p, cell),
                                        prep::ClipTriangleToCell(tris[kFar + 1].p, cell)};
  std::vector<uint8_t> raw;
  EXPECT_EQ(EncodeBlock(tris, refs, bounds, cell, &raw), 4u);  // a and c shared
  AlignedBuffer buffer;
  Expected<BlockView> v = ParseCopy(raw, &buffer, 1);
  ASSERT_TRUE(v.ok()) << v.status().message();
  ASSERT_EQ(v->triangle_count(), 2u);
  for (uint32_t t = 0; t < 2; ++t) {
    const PackedTriangle& source = tris[kFar + v->TriangleId(t) - 7];
    Vec3f p0, p1, p2;
    v->TriangleVertices(t, &p0, &p1, &p2);
    EXPECT_TRUE(p0 == source.p[0] && p1 == source.p[1] && p2 == source.p[2]) << "triangle " << t;
  }
}

// The traversal tests 4 triangles' edges at once and only the survivors one by one; the hits
// must be the ones every triangle tested alone gives (the closest, ties to the smaller id),
// also for rays aimed at vertices and edge midpoints, where an edge value is zero and the
// triangle test decides in double.
TEST(BlockView, IntersectAndOccludedEqualEveryTriangleTestedAlone) {
  Fixture f(400);
  AlignedBuffer buffer;
  Expected<BlockView> v = ParseCopy(f.raw, &buffer, 4);
  ASSERT_TRUE(v.ok()) << v.status().message();
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1.0f, 2.0f);
  std::uniform_int_distribution<uint32_t> pick(0, 399);
  int hits = 0, aimed = 0;
  for (int k = 0; k < 20000; ++k) {
    Ray ray;
    ray.origin = {u(rng), u(rng), u(rng)};
    const PackedTriangle& target = f.tris[pick(rng)];
    const Vec3f aim = k % 3 == 0 ? target.p[k % 2] : (target.p[0] + target.p[1]) * 0.5f;
    ray.direction = k % 5 == 4 ? Vec3f{u(rng), u(rng), u(rng)} : aim - ray.origin;
    ray.tmin = 0;
    ray.tmax = k % 7 == 0 ? 0.5f : std::numeric_limits<float>::infinity();
    aimed += k % 5 != 4;
    Hit expected;
    expected.t = ray.tmax;
    bool any = false;
    const RayTriangleSetup setup(ray);
    for (uint32_t t = 0; t < v->triangle_count(); ++t) {
      Vec3f p0, p1, p2;
      v->TriangleVertices(t, &p0, &p1, &p2);
      float th, bu, bv;
      if (!IntersectTriangle(setup, p0, p1, p2, ray.tmin, NextUp(expected.t), &th, &bu, &bv)) continue;
      if (th < ray.tmax) any = true;
      if (CloserThan(th, v->TriangleId(t), expected)) {
        expected.t = th;
        expected.triangle_id = v->TriangleId(t);
        expected.local_triangle = t;
      }
    }
    Hit got;
    got.t = ray.tmax;
    v->Intersect(ray, &got);
    ASSERT_EQ(got.triangle_id, expected.triangle_id) << "ray " << k;
    ASSERT_EQ(got.t, expected.t) << "ray " << k;
    ASSERT_EQ(v->Occluded(ray), any) << "ray " << k;
    hits += got.Valid();
  }
  EXPECT_GT(hits, 5000);
  EXPECT_GT(aimed, 10000);
}

TEST(BlockView, ConstantMaterialIsNotStoredPerTriangle) {
  Fixture f(50);
  for (auto& t : f.tris) t.material_and_flags = 4;
  EncodeInput in{f.tris, {}, f.refs, f.bounds, f.cell};
  BlockEncoder encoder;
  std::vector<uint8_t> raw;
  encoder.Encode(in, &raw);
  AlignedBuffer buffer;
  Expected<BlockView> v = ParseCopy(raw, &buffer, 9);
  ASSERT_TRUE(v.ok());
  EXPECT_FALSE(v->header().flags & kBlockPerTriangleMaterial);
  EXPECT_EQ(v->Material(7), 4u);
  EXPECT_LT(raw.size(), f.raw.size());
}

TEST(BlockView, WrongSizeIsRefusedWithTheBlockNamed) {
  Fixture f(20);
  AlignedBuffer buffer;
  std::vector<uint8_t> cut(f.raw.begin(), f.raw.end() - 16);
  Expected<BlockView> v = ParseCopy(cut, &buffer, 10);
  ASSERT_FALSE(v.ok());
  EXPECT_NE(v.status().message().find("block 10"), std::string::npos) << v.status().message();
}

TEST(BlockView, HostileHeadersAreRefused) {
  Fixture f(100);
  AlignedBuffer buffer;
  auto mutate = [&](auto change) {
    std::vector<uint8_t> raw = f.raw;
    BlockHeader h;
    std::memcpy(&h, raw.data(), sizeof h);
    change(h);
    std::memcpy(raw.data(), &h, sizeof h);
    return ParseCopy(raw, &buffer, 9).ok();
  };
  EXPECT_FALSE(mutate([](BlockHeader& h) { h.magic ^= 1; }));
  EXPECT_FALSE(mutate([](BlockHeader& h) { h.version = 99; }));
  EXPECT_FALSE(mutate([](BlockHeader& h) { h.triangle_count = 0xffffffffu; }));
  EXPECT_FALSE(mutate([](BlockHeader& h) { h.vertex_count += 1000; }));
  EXPECT_FALSE(mutate([](BlockHeader& h) { h.node_count = 0x7fffffff; }));
  EXPECT_FALSE(mutate([](BlockHeader& h) { h.flags |= 0x100; }));
}

// A block whose checksum was made again after its BVH was changed (a hostile-input review's
// forged stores rendered wrong images with exit 0): a box outside its parent's hides its
// triangles from the walk, an inverted one meets no ray.
TEST(BlockView, BvhBoxesOutsideTheirParentsOrInvertedAreRefused) {
  Fixture f(100);
  AlignedBuffer buffer;
  BlockHeader h;
  std::memcpy(&h, f.raw.data(), sizeof h);
  ASSERT_GT(h.node_count, 2u);
  const uint64_t nodes = BlockLayout::For(h).nodes;
  auto with_node_1 = [&](auto change) {
    std::vector<uint8_t> raw = f.raw;
    BvhNode n;
    std::memcpy(&n, raw.data() + nodes + sizeof(BvhNode), sizeof n);
    change(n);
    std::memcpy(raw.data() + nodes + sizeof(BvhNode), &n, sizeof n);
    Expected<BlockView> v = ParseCopy(raw, &buffer, 4);
    return v.ok() ? std::string() : v.status().message();
  };
  EXPECT_EQ(with_node_1([](BvhNode&) {}), "");
  EXPECT_NE(with_node_1([](BvhNode& n) { n.lower[1] -= 1; }).find("a BVH box outside its parent's"),
            std::string::npos);
  EXPECT_NE(with_node_1([](BvhNode& n) { n.upper[0] = n.lower[0] - 0.01f; }).find("an inverted BVH box"),
            std::string::npos);
  // What the reader checks a block's claims with: its ids and its vertices' box.
  Expected<BlockView> v = ParseCopy(f.raw, &buffer, 4);
  ASSERT_TRUE(v.ok());
  EXPECT_EQ(v->LargestTriangleId(), 1099u);
  const Bounds3f box = v->VertexBounds();
  for (int a = 0; a < 3; ++a) {
    EXPECT_GE(box.lower[a], 0.05f);
    EXPECT_LE(box.upper[a], 1.0f);
  }
}

TEST(BlockView, EverySingleByteCorruptionIsRefusedOrHarmless) {
  // Flip each byte in turn (the checksum is bypassed on purpose): Parse either refuses it or
  // gives a view whose traversal stays in bounds (the sanitizer build checks that).
  Fixture f(60);
  AlignedBuffer buffer;
  const Ray ray{{0.5f, 0.5f, -1}, {0.01f, 0.02f, 1}};
  for (size_t i = 0; i < f.raw.size(); ++i) {
    std::vector<uint8_t> raw = f.raw;
    raw[i] ^= 0xff;
    Expected<BlockView> v = ParseCopy(raw, &buffer, 9);
    if (!v.ok()) continue;
    Hit hit;
    v->Intersect(ray, &hit);
    (void)v->Occluded(ray);
  }
}

}  // namespace
}  // namespace raystack::store
