// The store holds the model faithfully: every triangle is in the blocks whose cells it
// overlaps, blocks stay inside their cells, and closest hits through the store equal brute
// force over the source triangles, bit for bit (t and triangle id), for 10^5 rays per model;
// any-hit agrees on whether there is a hit.

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <cstdio>
#include <map>
#include <random>
#include <set>

#include "common/base/temp_dir.h"
#include "common/store/store_reader.h"
#include "common/store/store_bvh.h"
#include "common/store/store_tracer.h"
#include "tests/geometry/test_meshes.h"
#include "tests/support/brute_force.h"
#include "tests/support/model_loader.h"
#include "tools/prep/clip.h"
#include "tools/prep/convert.h"

namespace raystack {
namespace {

using testing::BruteForce;
using testing::Tri;

struct Built {
  TempDir dir;
  std::unique_ptr<store::StoreReader> store;
};

Built ConvertToStore(const prep::ConvertOptions& base) {
  Expected<TempDir> dir = TempDir::Create();
  EXPECT_TRUE(dir.ok());
  prep::ConvertOptions options = base;
  options.output = dir->File("store");
  options.quiet = true;
  Expected<prep::ConvertReport> report = prep::Convert(options);
  EXPECT_TRUE(report.ok()) << report.status().message();
  Expected<std::unique_ptr<store::StoreReader>> store = store::StoreReader::Open(options.output);
  EXPECT_TRUE(store.ok()) << store.status().message();
  return {std::move(*dir), store.ok() ? std::move(*store) : nullptr};
}

// Every (block, triangle) pair overlaps; every triangle is somewhere; BVH boxes lie in cells.
void CheckPlacement(const store::StoreReader& s, const std::vector<Tri>& tris) {
  std::vector<uint8_t> seen(tris.size(), 0);
  std::vector<uint8_t> stored;
  store::AlignedBuffer scratch, raw;
  for (uint32_t b = 0; b < s.blocks().size(); ++b) {
    Expected<store::BlockView> v = s.Load(b, &stored, &scratch, &raw);
    ASSERT_TRUE(v.ok()) << v.status().message();
    const Bounds3f cell = v->cell();
    const store::BlockEntry& e = s.blocks()[b];
    ASSERT_EQ(cell.lower, (Vec3f{e.cell_lower[0], e.cell_lower[1], e.cell_lower[2]}));
    if (!v->nodes().empty()) {
      const BvhNode& root = v->nodes()[0];
      const Vec3f pad = cell.Extent() * 1e-5f;
      for (int a = 0; a < 3; ++a) {
        EXPECT_GE(root.lower[a], cell.lower[a] - pad[a]) << "block " << b;
        EXPECT_LE(root.upper[a], cell.upper[a] + pad[a]) << "block " << b;
      }
    }
    for (uint32_t t = 0; t < v->triangle_count(); ++t) {
      const uint32_t id = v->TriangleId(t);
      ASSERT_LT(id, tris.size());
      seen[id] = 1;
      Vec3f p[3];
      v->TriangleVertices(t, &p[0], &p[1], &p[2]);
      ASSERT_TRUE(p[0] == tris[id].p[0] && p[1] == tris[id].p[1] && p[2] == tris[id].p[2])
          << "block " << b << " changed triangle " << id;
      ASSERT_FALSE(prep::ClipTriangleToCell(p, cell).Empty())
          << "triangle " << id << " is in block " << b << " but does not overlap its cell";
    }
  }
  for (size_t i = 0; i < tris.size(); ++i) ASSERT_TRUE(seen[i]) << "triangle " << i << " is in no block";
}

// Half the rays aim at a point on a random triangle (they mostly hit), half go anywhere; a
// few are axis-parallel.
std::vector<Ray> MakeRays(const std::vector<Tri>& tris, const Bounds3f& box, int n, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const Vec3f lo = box.lower - box.Extent() * 0.25f, ext = box.Extent() * 1.5f;
  std::vector<Ray> rays;
  for (int i = 0; i < n; ++i) {
    Ray r;
    r.origin = lo + Vec3f{u(rng) * ext.x, u(rng) * ext.y, u(rng) * ext.z};
    if (i % 2 == 0) {
      const Tri& t = tris[rng() % tris.size()];
      float a = u(rng), b = u(rng);
      if (a + b > 1) { a = 1 - a; b = 1 - b; }
      r.direction = t.p[0] + (t.p[1] - t.p[0]) * a + (t.p[2] - t.p[0]) * b - r.origin;
    } else if (i % 16 == 1) {
      Vec3f d{0, 0, 0};
      d[static_cast<int>(rng() % 3)] = (rng() & 1) ? 1.0f : -1.0f;
      r.direction = d;
    } else {
      r.direction = Vec3f{u(rng) - 0.5f, u(rng) - 0.5f, u(rng) - 0.5f};
    }
    if (r.direction == Vec3f{0, 0, 0}) r.direction = {0, 1, 0};
    rays.push_back(r);
  }
  return rays;
}

// `extra` rays are traced after the n generated ones.
void CheckRays(const store::StoreReader& s, const std::vector<Tri>& tris, int n,
               const std::vector<Ray>& extra = {}) {
  BruteForce reference(tris);
  store::StoreTracer tracer(s);
  // The same blocks in one BVH (--mode bvh) must give the tracer's hits bit for bit.
  std::vector<store::AlignedBuffer> raw(s.blocks().size());
  std::vector<store::BlockView> views;
  std::vector<uint8_t> stored;
  store::AlignedBuffer scratch;
  for (uint32_t id = 0; id < s.blocks().size(); ++id) {
    Expected<store::BlockView> v = s.Load(id, &stored, &scratch, &raw[id]);
    ASSERT_TRUE(v.ok()) << v.status().message();
    views.push_back(*v);
  }
  const store::StoreBvh bvh(views);
  Bounds3f box;
  for (const Tri& t : tris)
    for (const Vec3f& p : t.p) box.Extend(p);
  int hits = 0, mismatches = 0;
  std::vector<Ray> rays = MakeRays(tris, box, n, 42);
  rays.insert(rays.end(), extra.begin(), extra.end());
  for (const Ray& ray : rays) {
    const Hit want = reference.Intersect(ray);
    Expected<Hit> got = s.blocks().empty() ? Expected<Hit>(Hit{}) : tracer.Intersect(ray);
    ASSERT_TRUE(got.ok()) << got.status().message();
    hits += want.Valid();
    if (!s.blocks().empty()) {  // any-hit agrees with the closest hit on whether there is one
      Expected<bool> occluded = tracer.Occluded(ray);
      ASSERT_TRUE(occluded.ok());
      EXPECT_EQ(*occluded, want.Valid());
      EXPECT_EQ(bvh.Occluded(ray), want.Valid());
    }
    const Hit one = bvh.Intersect(ray);
    EXPECT_EQ(0, std::memcmp(&one.t, &got->t, sizeof(float)));
    EXPECT_EQ(one.u, got->u);
    EXPECT_EQ(one.v, got->v);
    EXPECT_EQ(one.triangle_id, got->triangle_id);
    if (one.Valid()) {  // it names a copy of the triangle it hit
      ASSERT_LT(one.block_id, views.size());
      ASSERT_LT(one.local_triangle, views[one.block_id].triangle_count());
      EXPECT_EQ(views[one.block_id].TriangleId(one.local_triangle), one.triangle_id);
    }
    if (got->triangle_id != want.triangle_id || (want.Valid() && got->t != want.t)) {
      if (++mismatches <= 5)
        ADD_FAILURE() << "ray (" << ray.origin.x << "," << ray.origin.y << "," << ray.origin.z
                      << ") dir (" << ray.direction.x << "," << ray.direction.y << ","
                      << ray.direction.z << "): store hit " << got->triangle_id << " at t="
                      << got->t << ", brute force " << want.triangle_id << " at t=" << want.t;
    }
  }
  EXPECT_EQ(mismatches, 0);
  EXPECT_GT(hits, n / 4) << "too few rays hit: the test would prove little";
}

TEST(StoreModel, GeneratedSphere) {
  prep::ConvertOptions o;
  o.generate = "sphere:50000";
  Built b = ConvertToStore(o);
  ASSERT_TRUE(b.store);
  const std::vector<Tri> tris = testing::GenerateTriangles(o.generate);
  CheckPlacement(*b.store, tris);
  CheckRays(*b.store, tris, 100000);
}

TEST(StoreModel, GeneratedSoupWithSmallBlocks) {
  prep::ConvertOptions o;
  o.generate = "soup:20000";
  o.target_block_bytes = 4096;
  o.max_block_bytes = 16384;
  Built b = ConvertToStore(o);
  ASSERT_TRUE(b.store);
  for (const store::BlockEntry& e : b.store->blocks()) EXPECT_LE(e.raw_bytes, 16384u);
  const std::vector<Tri> tris = testing::GenerateTriangles(o.generate);
  CheckPlacement(*b.store, tris);
  CheckRays(*b.store, tris, 100000);
}

TEST(StoreModel, PartitionedOnDiskMatchesInMemory) {
  // A memory limit this small forces the external partition path; it must give a store
  // with the same hits.
  prep::ConvertOptions o;
  o.generate = "spheres:200000";
  o.memory_limit_bytes = 64ull << 20;
  Built b = ConvertToStore(o);
  ASSERT_TRUE(b.store);
  const std::vector<Tri> tris = testing::GenerateTriangles(o.generate);
  CheckPlacement(*b.store, tris);
  CheckRays(*b.store, tris, 20000);
}

// The conference room's hit just outside its box (ConferenceRoomHitOutsideItsBox) through the
// converter, a triangle a leaf so the closest and the farther hit sit in different leaves of the
// block's BVH: the store's walk and the one BVH give brute force's hit. Without the margin in
// the box tests the store returned the farther one.
TEST(StoreModel, AHitJustOutsideItsBoxMatchesBruteForce) {
  const geometry_test::HitOutsideItsBox c = geometry_test::ConferenceRoomHitOutsideItsBox();
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  const std::string obj = dir->File("five.obj");
  {
    std::FILE* f = std::fopen(obj.c_str(), "w");
    ASSERT_NE(f, nullptr);
    for (int i = 0; i < 5; ++i) {
      for (const Vec3f& p : c.triangles[i].p)  // 9 digits: the floats exactly
        std::fprintf(f, "v %.9g %.9g %.9g\n", double{p.x}, double{p.y}, double{p.z});
      std::fprintf(f, "f %d %d %d\n", 3 * i + 1, 3 * i + 2, 3 * i + 3);
    }
    std::fclose(f);
  }
  prep::ConvertOptions o;
  o.inputs = {obj};
  o.bvh.max_leaf_size = 1;
  Built b = ConvertToStore(o);
  ASSERT_TRUE(b.store);
  const std::vector<Tri> tris = testing::LoadTriangles(obj);
  ASSERT_EQ(tris.size(), 5u);
  const Ray ray{c.origin, c.direction};
  const Hit want = BruteForce(tris).Intersect(ray);
  ASSERT_EQ(want.triangle_id, 3u);  // 76502 of the room
  CheckRays(*b.store, tris, 400, {ray});
}

// Hostile geometry through the whole pipeline (issue 6): needles (10 long, 1e-6 wide), slivers
// with nearly collinear vertices, exactly zero-area triangles (dropped by the reader), a
// triangle spanning the whole scene, and a lattice of axis-aligned squares traced by rays
// lying exactly in their planes (grazing) or along their edges (axis-parallel). The store's
// hits equal brute force's, and the converter keeps every triangle in a bounded store.
TEST(StoreModel, NeedlesSliversZeroAreaAndAHugeTriangleMatchBruteForce) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  const std::string obj = dir->File("hostile.obj");
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> coord(-50, 50), unit(0, 1);
  {
    std::FILE* f = std::fopen(obj.c_str(), "w");
    int v = 0;
    auto tri = [&](Vec3f a, Vec3f b, Vec3f c) {
      for (const Vec3f& p : {a, b, c}) {
        std::fprintf(f, "v %.9g %.9g %.9g\n", double{p.x}, double{p.y}, double{p.z});
      }
      std::fprintf(f, "f %d %d %d\n", v + 1, v + 2, v + 3);
      v += 3;
    };
    tri({-1000, -1000, -60}, {3000, -1000, 60}, {-1000, 3000, 0});  // spans the whole scene
    for (int i = 0; i < 3000; ++i) {
      const Vec3f a{coord(rng), coord(rng), coord(rng)};
      const Vec3f d = Normalize(Vec3f{unit(rng) - 0.5f, unit(rng) - 0.5f, unit(rng) - 0.5f});
      switch (i % 3) {
        case 0: tri(a, a + d * 10, a + d * 10 + Vec3f{1e-6f, 0, 1e-6f}); break;  // needle
        case 1: tri(a, a + d * 5, a + d * 10.0f + Vec3f{0, 1e-4f, 0}); break;   // sliver
        default: tri(a, a + d * 5, a + d * 10); break;  // collinear (zero area in double)
      }
    }
    for (int x = -20; x < 20; x += 2) {  // axis-aligned unit squares on integer planes
      for (int y = -20; y < 20; y += 2) {
        const Vec3f p{float(x), float(y), 7};
        tri(p, p + Vec3f{1, 0, 0}, p + Vec3f{1, 1, 0});
        tri(p, p + Vec3f{1, 1, 0}, p + Vec3f{0, 1, 0});
      }
    }
    std::fclose(f);
  }
  prep::ConvertOptions o;
  o.inputs = {obj};
  o.target_block_bytes = 4096;
  o.max_block_bytes = 16384;
  Built b = ConvertToStore(o);
  ASSERT_TRUE(b.store);
  const std::vector<Tri> tris = testing::LoadTriangles(obj);
  ASSERT_GT(tris.size(), 2000u);
  CheckPlacement(*b.store, tris);
  for (const store::BlockEntry& e : b.store->blocks()) EXPECT_LE(e.raw_bytes, 16384u);

  std::vector<Ray> grazing;
  for (int i = 0; i < 20000; ++i) {
    Ray r;
    const float x = std::floor(coord(rng) * 0.4f), y = std::floor(coord(rng) * 0.4f);
    if (i % 2 == 0) {  // in the plane z = 7, any direction within it
      r.origin = {coord(rng), coord(rng), 7};
      r.direction = {unit(rng) - 0.5f, unit(rng) - 0.5f, 0};
    } else {  // along an edge or a diagonal of the lattice, or straight down through a corner
      r.origin = {x, y, i % 4 == 1 ? 7.0f : 30.0f};
      r.direction = i % 4 == 1 ? Vec3f{1, (i % 8 == 1) ? 0.0f : 1.0f, 0} : Vec3f{0, 0, -1};
    }
    if (r.direction == Vec3f{0, 0, 0}) r.direction = {1, 0, 0};
    grazing.push_back(r);
  }
  CheckRays(*b.store, tris, 100000, grazing);
}

class SharedModelTest : public ::testing::TestWithParam<const char*> {};

TEST_P(SharedModelTest, HitsEqualBruteForce) {
  const std::string dir = testing::SharedModels();
  if (dir.empty())
    GTEST_SKIP() << "no shared models folder (../shared/models): the real-model layer is skipped";
  const std::string path = dir + "/" + GetParam();
  prep::ConvertOptions o;
  o.inputs = {path};
  Built b = ConvertToStore(o);
  ASSERT_TRUE(b.store);
  const std::vector<Tri> tris = testing::LoadTriangles(path);
  ASSERT_FALSE(tris.empty());
  CheckPlacement(*b.store, tris);
  CheckRays(*b.store, tris, 100000);
}

// A real model with normals through the partition pass (--mem-limit 64), which once failed on
// the conference room ("records of different sizes cannot be read by range").
TEST(StoreModel, SharedModelWithNormalsPartitionedOnDisk) {
  const std::string dir = testing::SharedModels();
  if (dir.empty())
    GTEST_SKIP() << "no shared models folder (../shared/models): the real-model layer is skipped";
  const std::string path = dir + "/conference.obj";
  prep::ConvertOptions o;
  o.inputs = {path};
  o.memory_limit_bytes = 64ull << 20;
  Built b = ConvertToStore(o);
  ASSERT_TRUE(b.store);
  const std::vector<Tri> tris = testing::LoadTriangles(path);
  CheckPlacement(*b.store, tris);
  CheckRays(*b.store, tris, 20000);
}

INSTANTIATE_TEST_SUITE_P(Models, SharedModelTest,
                         ::testing::Values("CornellBox-Original.obj", "bun_zipper.ply",
                                           "dragon_vrip.ply", "conference.obj", "motorBike.obj"),
                         [](const auto& param_info) {
                           std::string name = param_info.param;
                           for (char& c : name)
                             if (!isalnum(static_cast<unsigned char>(c))) c = '_';
                           return name;
                         });

}  // namespace
}  // namespace raystack

namespace raystack {
namespace {

// What the model has is stored, and only that: normals, uvs and per-triangle materials of an
// OBJ come back from the blocks; a model without them has blocks without them.
TEST(StoreModel, AttributesTheModelHasAreStoredAndOnlyThose) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  const std::string obj = dir->File("attr.obj"), mtl = dir->File("attr.mtl");
  {
    std::FILE* f = std::fopen(mtl.c_str(), "w");
    std::fputs("newmtl red\nKd 1 0 0\nnewmtl lamp\nKe 5 5 5\n", f);
    std::fclose(f);
    f = std::fopen(obj.c_str(), "w");
    std::fputs("mtllib attr.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
               "vn 0 0 1\nvn 0 0.6 0.8\nvt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\n"
               "usemtl red\nf 1/1/1 2/2/1 3/3/2\nusemtl lamp\nf 2/2/1 4/4/2 3/3/2\n", f);
    std::fclose(f);
  }
  prep::ConvertOptions o;
  o.inputs = {obj};
  Built b = ConvertToStore(o);
  ASSERT_TRUE(b.store);
  EXPECT_EQ(b.store->summary().model_flags,
            store::kModelHasNormals | store::kModelHasUvs | store::kModelHasMaterials);
  ASSERT_EQ(b.store->materials().size(), 2u);
  EXPECT_STREQ(b.store->materials()[1].name, "lamp");
  EXPECT_EQ(b.store->materials()[1].ke[0], 5.0f);
  std::vector<uint8_t> stored;
  store::AlignedBuffer scratch, raw;
  ASSERT_EQ(b.store->blocks().size(), 1u);
  Expected<store::BlockView> v = b.store->Load(0, &stored, &scratch, &raw);
  ASSERT_TRUE(v.ok()) << v.status().message();
  ASSERT_TRUE(v->has_normals());
  ASSERT_TRUE(v->has_uvs());
  for (uint32_t t = 0; t < v->triangle_count(); ++t) {
    EXPECT_EQ(v->Material(t), v->TriangleId(t));  // triangle 0 is red (0), 1 is lamp (1)
    const Vec3f n2 = v->Normal(v->VertexIndex(t, 2));
    EXPECT_EQ(n2.y, 0.6f);
    EXPECT_EQ(n2.z, 0.8f);
  }

  prep::ConvertOptions plain;
  plain.generate = "sphere:2000";
  Built p = ConvertToStore(plain);
  ASSERT_TRUE(p.store);
  EXPECT_EQ(p.store->summary().model_flags, 0u);
  for (uint32_t id = 0; id < p.store->blocks().size(); ++id) {
    Expected<store::BlockView> pv = p.store->Load(id, &stored, &scratch, &raw);
    ASSERT_TRUE(pv.ok());
    EXPECT_FALSE(pv->has_normals());
    EXPECT_FALSE(pv->has_uvs());
    EXPECT_FALSE(pv->header().flags & store::kBlockPerTriangleMaterial);
    EXPECT_EQ(pv->Material(0), store::kNoMaterial);
  }
}

}  // namespace


// Only the materials faces use are stored, numbered in order of first use across input files
// (each with its own MTL), and every face, emitter and replicated copy keeps its own (the day's
// review asked for this case: two models, emitters, --replicate).
TEST(StoreModel, MaterialsOfSeveralModelsAreRenumberedFaceByFace) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  const auto write = [&](const std::string& name, const std::string& text) {
    std::FILE* f = std::fopen(dir->File(name).c_str(), "w");
    std::fputs(text.c_str(), f);
    std::fclose(f);
  };
  write("a.mtl", "newmtl A0\nKd 1 0 0\nnewmtl A1\nKd 0 1 0\nnewmtl lightA\nKe 5 5 5\n");
  write("a.obj", "mtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
                 "usemtl lightA\nf 1 2 3\nusemtl A1\nf 2 4 3\n");
  write("b.mtl", "newmtl B0\nKd 0 0 1\nnewmtl lightB\nKe 3 3 3\nnewmtl B2\nKd 1 1 0\n");
  write("b.obj", "mtllib b.mtl\nv 0 0 1\nv 1 0 1\nv 0 1 1\nv 1 1 1\n"
                 "usemtl B2\nf 1 2 3\nusemtl lightB\nf 2 4 3\nusemtl nodef\nf 1 2 4\n");
  const std::vector<std::string> names = {"lightA", "A1", "B2", "lightB", "nodef"};
  for (const int copies : {1, 2}) {
    SCOPED_TRACE(copies);
    prep::ConvertOptions o;
    o.inputs = {dir->File("a.obj"), dir->File("b.obj")};
    o.replicate = {copies, 1, 1};
    Built b = ConvertToStore(o);
    ASSERT_TRUE(b.store);
    ASSERT_EQ(b.store->materials().size(), names.size());
    for (size_t m = 0; m < names.size(); ++m)
      EXPECT_STREQ(b.store->materials()[m].name, names[m].c_str()) << m;
    // Triangle i of a copy is the model's triangle i % 5, whose store material is i % 5.
    std::vector<uint8_t> stored;
    store::AlignedBuffer scratch, raw;
    size_t seen = 0;
    for (uint32_t id = 0; id < b.store->blocks().size(); ++id) {
      Expected<store::BlockView> v = b.store->Load(id, &stored, &scratch, &raw);
      ASSERT_TRUE(v.ok()) << v.status().message();
      for (uint32_t t = 0; t < v->triangle_count(); ++t, ++seen)
        EXPECT_EQ(v->Material(t), v->TriangleId(t) % 5) << "triangle " << v->TriangleId(t);
    }
    EXPECT_GE(seen, 5u * static_cast<size_t>(copies));
    // lights.bin: the two emissive faces of every copy, with their store materials.
    ASSERT_EQ(b.store->emitters().size(), 2u * static_cast<size_t>(copies));
    for (const store::EmitterRecord& e : b.store->emitters()) {
      EXPECT_TRUE(e.triangle % 5 == 0 || e.triangle % 5 == 3) << e.triangle;
      EXPECT_EQ(e.material, e.triangle % 5) << e.triangle;
    }
  }
}}  // namespace raystack
