// The ray stack's contract: the three modes compute the same image bit for bit, the image's
// depth equals brute-force ray casting, and the cache budget holds.

#include "slave/render_engine.h"

#include <gtest/gtest.h>

#include <numbers>

#include <cmath>

#include "slave/ray_thread.h"
#include "tests/slave/render_fixture.h"
#include "tests/support/brute_force.h"
#include "tests/support/model_loader.h"
#include "tests/support/older_store.h"

namespace raystack::testing {
namespace {

using slave::EngineOptions;
using slave::TraceMode;

render::Scene SpheresScene(const store::StoreReader& store, render::IntegratorType type,
                           int spp) {
  render::Scene scene;
  scene.cameras.push_back(FramingCamera(store, 96, 72));
  const Bounds3f b = store.model_bounds();
  scene.lights.push_back({b.upper + (b.upper - b.lower) * 0.5f, {40, 40, 40}});
  scene.lights.push_back({Vec3f{b.lower.x, b.upper.y * 2, b.upper.z}, {10, 5, 5}});
  scene.background = {0.1f, 0.1f, 0.2f};
  scene.integrator.type = type;
  scene.integrator.spp = spp;
  scene.integrator.max_depth = type == render::IntegratorType::kPath ? 6 : 3;
  scene.integrator.seed = 7;
  return scene;
}

uint64_t Budget(const store::StoreReader& store, int blocks) {
  uint64_t largest = 0;
  for (const auto& e : store.blocks()) largest = std::max<uint64_t>(largest, e.raw_bytes);
  return blocks * ((largest + 63) & ~uint64_t{63});
}

EngineOptions Mode(TraceMode mode, uint64_t cache_bytes, int threads = 2) {
  EngineOptions o;
  o.mode = mode;
  o.cache_bytes = cache_bytes;
  o.threads = threads;
  o.result_batch = 64;
  return o;
}

class ModesAgree : public ::testing::TestWithParam<std::tuple<render::MaterialType, render::IntegratorType>> {};

TEST_P(ModesAgree, BitIdenticalRgbaAndZ) {
  static TestStore s = BuildGenerated("spheres:60000");
  ASSERT_GT(s.reader->blocks().size(), 20u);
  const auto [material, integrator] = GetParam();
  render::Scene scene = SpheresScene(*s.reader, integrator,
                                     integrator == render::IntegratorType::kPath ? 3 : 1);
  scene.default_material.type = material;
  scene.default_material.albedo = {0.7f, 0.6f, 0.5f};
  const RenderOutcome incore = Render(*s.reader, scene, Mode(TraceMode::kIncore, 0));
  ASSERT_TRUE(incore.status.ok()) << incore.status.message();
  {
    SCOPED_TRACE("bvh");  // one tree over every triangle instead of the blocks' trees
    const RenderOutcome r = Render(*s.reader, scene, Mode(TraceMode::kBvh, 0));
    ASSERT_TRUE(r.status.ok()) << r.status.message();
    EXPECT_TRUE(SameBits(r.image.rgba, incore.image.rgba));
    EXPECT_TRUE(SameBits(r.image.z, incore.image.z));
    EXPECT_TRUE(SameBits(r.image.normal, incore.image.normal));
    EXPECT_EQ(r.stats.samples, incore.stats.samples);
    EXPECT_EQ(r.stats.rays_total, incore.stats.rays_total);
    EXPECT_EQ(r.stats.blocks_distinct, r.stats.block_count);
    EXPECT_GT(r.stats.bvh_build_seconds, 0);
  }
  for (int blocks : {3, 12}) {
    for (TraceMode mode : {TraceMode::kStack, TraceMode::kSync}) {
      SCOPED_TRACE(std::string(slave::TraceModeName(mode)) + " with a budget of " +
                   std::to_string(blocks) + " blocks");
      const uint64_t budget = Budget(*s.reader, blocks);
      const RenderOutcome r = Render(*s.reader, scene, Mode(mode, budget));
      ASSERT_TRUE(r.status.ok()) << r.status.message();
      EXPECT_TRUE(SameBits(r.image.rgba, incore.image.rgba));
      EXPECT_TRUE(SameBits(r.image.z, incore.image.z));
      EXPECT_TRUE(SameBits(r.image.normal, incore.image.normal));
      EXPECT_LE(r.stats.cache_peak_bytes, budget);
      EXPECT_GT(r.stats.blocks_loaded, r.stats.blocks_distinct / 2);
      EXPECT_EQ(r.stats.samples, incore.stats.samples);
      EXPECT_EQ(r.stats.rays_total, incore.stats.rays_total);
    }
  }
  // The image is not trivially black or uniform.
  float lo = 1e30f, hi = -1e30f;
  for (size_t i = 0; i < incore.image.rgba.size(); i += 4) {
    lo = std::min(lo, incore.image.rgba[i]);
    hi = std::max(hi, incore.image.rgba[i]);
  }
  EXPECT_LT(lo, hi);
}

INSTANTIATE_TEST_SUITE_P(
    Materials, ModesAgree,
    ::testing::Values(std::make_tuple(render::MaterialType::kDiffuse, render::IntegratorType::kWhitted),
                      std::make_tuple(render::MaterialType::kMirror, render::IntegratorType::kWhitted),
                      std::make_tuple(render::MaterialType::kGlass, render::IntegratorType::kWhitted),
                      std::make_tuple(render::MaterialType::kDiffuse, render::IntegratorType::kPath),
                      std::make_tuple(render::MaterialType::kGlass, render::IntegratorType::kPath)));

// bvh mode puts the shadow rays of primary hits aside and traces them as packets once the rays
// fed with them are done, or once it holds RayThread::kMaxShadowsAside (16,384) of them. With
// 40 lights and tiles of 4,096 samples, tiles hold more than that: both ways are taken.
TEST(RenderEngine, BvhModeWithMoreShadowRaysThanItPutsAsideRendersTheSameImage) {
  static TestStore s = BuildGenerated("spheres:60000");
  render::Scene scene = SpheresScene(*s.reader, render::IntegratorType::kWhitted, 4);
  const Bounds3f b = s.reader->model_bounds();
  const Vec3f size = b.upper - b.lower;
  while (scene.lights.size() < 40) {
    const float k = static_cast<float>(scene.lights.size());
    const Vec3f offset{size.x * (k / 20 - 1), size.y * 0.3f, size.z * (k / 40)};
    scene.lights.push_back({b.upper + offset, {2, 2, 2}});
  }
  const int tile = 32;  // 32 x 32 pixels x 4 samples: one feed of 4,096 samples a tile
  const RenderOutcome incore = Render(*s.reader, scene, Mode(TraceMode::kIncore, 0), tile);
  ASSERT_TRUE(incore.status.ok()) << incore.status.message();
  const RenderOutcome bvh = Render(*s.reader, scene, Mode(TraceMode::kBvh, 0), tile);
  ASSERT_TRUE(bvh.status.ok()) << bvh.status.message();
  // Put aside up to the limit and never past it.
  EXPECT_EQ(bvh.stats.peak_shadows_aside, slave::RayThread::kMaxShadowsAside);
  EXPECT_TRUE(SameBits(bvh.image.rgba, incore.image.rgba));
  EXPECT_TRUE(SameBits(bvh.image.z, incore.image.z));
  EXPECT_EQ(bvh.stats.rays_total, incore.stats.rays_total);
}

TEST(RenderEngine, DepthEqualsBruteForceAtEveryPixel) {
  const std::string spec = "spheres:40000";
  TestStore s = BuildGenerated(spec);
  const BruteForce brute(GenerateTriangles(spec));
  render::Scene scene = SpheresScene(*s.reader, render::IntegratorType::kWhitted, 1);
  const RenderOutcome r = Render(*s.reader, scene, Mode(TraceMode::kStack, Budget(*s.reader, 4)));
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  const render::Camera camera(scene.cameras[0]);
  int hits = 0, mismatches = 0;
  for (int y = 0; y < camera.height(); ++y) {
    for (int x = 0; x < camera.width(); ++x) {
      const Ray ray = camera.Generate(static_cast<float>(x) + 0.5f, static_cast<float>(y) + 0.5f);
      const Hit h = brute.Intersect(ray);
      const float z = r.image.z[static_cast<size_t>(y) * camera.width() + x];
      const float expected = h.Valid() ? h.t : std::numeric_limits<float>::infinity();
      if (h.Valid()) ++hits;
      if (std::memcmp(&z, &expected, sizeof z) != 0) ++mismatches;
    }
  }
  EXPECT_EQ(mismatches, 0);
  EXPECT_GT(hits, camera.width() * camera.height() / 4);
}

// The same framing from 1e5 times as far (the field of view narrowed to match) costs about as
// many (ray, block) steps as the near one: a far camera's primary rays start near
// the model (primary_approach.h). From the camera itself, the box tests' margins (ulps of the
// camera's coordinates) took in every block a ray passed by: 75 times the steps, and the
// dragon's frame from 1e5 away took 7.6 s against 0.08 s from 1e3.
TEST(RenderEngine, AFarCameraCostsWhatANearOneDoes) {
  TestStore s = BuildGenerated("spheres:40000");
  render::Scene near_scene = SpheresScene(*s.reader, render::IntegratorType::kWhitted, 1);
  render::Scene far_scene = near_scene;
  render::CameraDesc& far = far_scene.cameras[0];
  const Vec3f back = far.position - far.look_at;
  far.position = far.look_at + back * 1e5f;
  far.fov_y_deg = static_cast<float>(
      2 * std::atan(std::tan(double{far.fov_y_deg} * std::numbers::pi / 360) / 1e5) * 360 /
      std::numbers::pi);
  const RenderOutcome n = Render(*s.reader, near_scene, Mode(TraceMode::kStack, Budget(*s.reader, 64)));
  const RenderOutcome f = Render(*s.reader, far_scene, Mode(TraceMode::kStack, Budget(*s.reader, 64)));
  ASSERT_TRUE(n.status.ok()) << n.status.message();
  ASSERT_TRUE(f.status.ok()) << f.status.message();
  EXPECT_LT(f.stats.block_visits, 2 * n.stats.block_visits)
      << "far " << f.stats.block_visits << ", near " << n.stats.block_visits;
  // And it sees the model (nearly a parallel projection of it, so a smaller one than the near
  // camera's perspective shows), lit about as brightly (from the camera itself it was unlit).
  int hits[2] = {};
  double lit[2] = {};
  for (int k = 0; k < 2; ++k) {
    const image::ImageLayers& image = k == 0 ? n.image : f.image;
    for (size_t i = 0; i < image.z.size(); ++i) {
      if (!std::isfinite(image.z[i])) continue;
      ++hits[k];
      lit[k] += double{image.rgba[4 * i]};
    }
  }
  ASSERT_GT(hits[0], 0);
  EXPECT_GT(hits[1], static_cast<int>(f.image.z.size()) / 20);
  EXPECT_NEAR((lit[1] / hits[1]) / (lit[0] / hits[0]), 1.0, 0.5);
}

TEST(RenderEngine, UnreachedBlocksAreNeverRead) {
  TestStore s = BuildGenerated("spheres:60000");
  render::Scene scene = SpheresScene(*s.reader, render::IntegratorType::kWhitted, 1);
  scene.lights.clear();  // primary rays only
  // A narrow view of one corner of the model.
  scene.cameras[0].fov_y_deg = 3;
  const RenderOutcome r = Render(*s.reader, scene, Mode(TraceMode::kStack, Budget(*s.reader, 64)));
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  EXPECT_EQ(r.stats.rays[static_cast<int>(slave::RayType::kShadow)], 0u);
  EXPECT_LT(r.stats.blocks_distinct, s.reader->blocks().size() / 2);
  EXPECT_EQ(r.stats.blocks_loaded, r.stats.blocks_distinct);  // the budget holds them all
}

// The stats split a frame's CPU time between the ray threads and the loader's threads (what
// bounds a frame on a machine with fewer cores than threads). Each thread's own clock, over the
// frame only: a ray thread cannot use more CPU than the frame's wall time.
TEST(RenderEngine, CpuTimeIsCountedByThreadKind) {
  static TestStore s = BuildGenerated("spheres:60000");
  const render::Scene scene = SpheresScene(*s.reader, render::IntegratorType::kWhitted, 1);
  for (TraceMode mode : {TraceMode::kStack, TraceMode::kSync}) {
    SCOPED_TRACE(slave::TraceModeName(mode));
    const RenderOutcome r = Render(*s.reader, scene, Mode(mode, Budget(*s.reader, 4)));
    ASSERT_TRUE(r.status.ok()) << r.status.message();
    ASSERT_GT(r.stats.blocks_loaded, 0u);
    EXPECT_GT(r.stats.ray_cpu_seconds, 0);
    EXPECT_LE(r.stats.ray_cpu_seconds, r.stats.threads * r.stats.seconds + 0.01);
    if (mode == TraceMode::kStack) {
      EXPECT_GT(r.stats.loader_cpu_seconds, 0);
    } else {
      EXPECT_EQ(r.stats.loader_cpu_seconds, 0);  // sync: each ray thread reads for itself
    }
  }
}

TEST(RenderEngine, NoSpecularRaysWithoutSpecularMaterials) {
  TestStore s = BuildGenerated("sphere:5000");
  const RenderOutcome r = Render(*s.reader, SpheresScene(*s.reader, render::IntegratorType::kWhitted, 1),
                                 Mode(TraceMode::kStack, Budget(*s.reader, 8)));
  ASSERT_TRUE(r.status.ok());
  EXPECT_EQ(r.stats.rays[static_cast<int>(slave::RayType::kSpecular)], 0u);
  EXPECT_GT(r.stats.rays[static_cast<int>(slave::RayType::kShadow)], 0u);
}

TEST(RenderEngine, BudgetSmallerThanABlockIsAClearError) {
  TestStore s = BuildGenerated("sphere:5000");
  Expected<std::unique_ptr<slave::RenderEngine>> e =
      slave::RenderEngine::Create(*s.reader, Mode(TraceMode::kStack, 1000));
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.status().message().find("smaller than the largest block"), std::string::npos)
      << e.status().message();
  // The least --cache-mb it names (in MiB, with its fraction: this store's blocks are far
  // under 1 MiB) is enough.
  const std::string& m = e.status().message();
  const size_t at = m.find("give --cache-mb at least ");
  ASSERT_NE(at, std::string::npos) << m;
  const double mb = std::stod(m.substr(at + 25));
  EXPECT_LT(mb, 1.0) << m;
  EXPECT_TRUE(slave::RenderEngine::Create(
                  *s.reader, Mode(TraceMode::kStack, static_cast<uint64_t>(mb * 1024 * 1024)))
                  .ok())
      << m;
}

// Found by a scale review: --mode bvh on a store of more triangles than the one tree numbers
// read every block and built the tree, then stopped on an internal check ("group < 2^29"). The
// store's count is looked at first: its summary is rewritten here to claim 2^29 + 1 triangles.
TEST(RenderEngine, BvhModeRefusesAStoreLargerThanItsTreeAtOnce) {
  TestStore s = BuildGenerated("sphere:5000");
  const std::string dir = s.reader->dir();
  s.reader.reset();
  ASSERT_TRUE(raystack::testing::RewriteSummary(dir, [](store::StoreSummary* summary) {
    summary->source_triangles = WideBvh::kMaxTriangles + 1;
  }));
  Expected<std::unique_ptr<store::StoreReader>> reader = store::StoreReader::Open(dir);
  ASSERT_TRUE(reader.ok()) << reader.status().message();
  Expected<std::unique_ptr<slave::RenderEngine>> bvh =
      slave::RenderEngine::Create(**reader, Mode(TraceMode::kBvh, 0));
  ASSERT_FALSE(bvh.ok());
  EXPECT_NE(bvh.status().message().find("536870913 triangles; --mode bvh builds one tree of at "
                                        "most 536870912: --mode stack renders it"),
            std::string::npos) << bvh.status().message();
  EXPECT_TRUE(slave::RenderEngine::Create(**reader, Mode(TraceMode::kStack, Budget(**reader, 8))).ok());
}

TEST(RenderEngine, CacheBudgetHoldsFromAFewBlocksUp) {
  TestStore s = BuildGenerated("spheres:60000");
  render::Scene scene = SpheresScene(*s.reader, render::IntegratorType::kWhitted, 1);
  scene.default_material.type = render::MaterialType::kMirror;
  for (int blocks : {1, 2, 5, 40}) {
    for (TraceMode mode : {TraceMode::kStack, TraceMode::kSync}) {
      const uint64_t budget = Budget(*s.reader, blocks);
      const RenderOutcome r = Render(*s.reader, scene, Mode(mode, budget, 3));
      ASSERT_TRUE(r.status.ok()) << r.status.message();
      EXPECT_LE(r.stats.cache_peak_bytes, budget) << blocks << " blocks";
      EXPECT_GT(r.stats.cache_peak_bytes, 0u);
    }
  }
}

// Reads from the page cache (the test's store was just written) are CPU work: the loader thread
// makes them itself, but for bursts of more than a few runs. Once reads have to wait (an
// injected latency, as a slow disk or network filesystem), it hands them to I/O threads, which
// start as reads pile up, up to io_threads. How many runs a batch holds depends on when the
// loader gets a core (it runs SCHED_BATCH: later on a busy machine, with more asks gathered),
// so the shares of who reads are bounds, not counts: alone, the loader made 52-72% of the
// page-cache reads; beside other tests, down to 45%.
TEST(RenderEngine, IoThreadsStartWhenReadsWait) {
  static TestStore s = BuildGenerated("spheres:60000");
  const render::Scene scene = SpheresScene(*s.reader, render::IntegratorType::kWhitted, 1);
  EngineOptions fast = Mode(TraceMode::kStack, Budget(*s.reader, 6));
  fast.loader.io_threads = 32;
  const RenderOutcome a = Render(*s.reader, scene, fast);
  ASSERT_TRUE(a.status.ok()) << a.status.message();
  ASSERT_GT(a.stats.reads, 100u);
  // The loader reads itself; bursts go to a few threads (as many as the cores).
  EXPECT_GT(a.stats.loader_reads, 0u);
  EXPECT_LT(a.stats.io_workers, 16u);

  EngineOptions slow = fast;
  slow.loader.io_threads = 8;
  slow.faults.io_latency_us = 1000;
  const RenderOutcome b = Render(*s.reader, scene, slow);
  ASSERT_TRUE(b.status.ok()) << b.status.message();
  EXPECT_LE(b.stats.loader_reads, 2u);  // at most the first two: they waited
  EXPECT_EQ(b.stats.io_workers, 8u);
  EXPECT_TRUE(SameBits(a.image.rgba, b.image.rgba));
}

// Reads past the page cache (--direct-io) deliver the same bytes: a stack and a sync render
// that reload blocks many times equal the buffered ones bit for bit, and say how they read.
TEST(RenderEngine, DirectReadsRenderTheSameImage) {
  TestStore s = BuildGenerated("spheres:30000");
  const std::unique_ptr<store::StoreReader> direct = OpenDirect(s);
  ASSERT_TRUE(direct);
  const render::Scene scene = SpheresScene(*s.reader, render::IntegratorType::kWhitted, 1);
  for (TraceMode mode : {TraceMode::kStack, TraceMode::kSync}) {
    SCOPED_TRACE(slave::TraceModeName(mode));
    const RenderOutcome a = Render(*s.reader, scene, Mode(mode, Budget(*s.reader, 4)));
    const RenderOutcome b = Render(*direct, scene, Mode(mode, Budget(*s.reader, 4)));
    ASSERT_TRUE(a.status.ok()) << a.status.message();
    ASSERT_TRUE(b.status.ok()) << b.status.message();
    EXPECT_FALSE(a.stats.direct_reads);
    EXPECT_TRUE(b.stats.direct_reads);
    // The stack's loader keeps direct reads in flight with Linux AIO; sync reads them itself.
    EXPECT_FALSE(a.stats.aio_reads);
    EXPECT_EQ(b.stats.aio_reads, mode == TraceMode::kStack);
    EXPECT_GT(b.stats.blocks_loaded, b.stats.blocks_distinct);  // evicted and read again
    EXPECT_TRUE(SameBits(a.image.rgba, b.image.rgba));
    EXPECT_TRUE(SameBits(a.image.z, b.image.z));
    // One read in flight at a time: every other run waits in the loader's queue for the slot.
    EngineOptions one = Mode(mode, Budget(*s.reader, 4));
    one.loader.io_threads = 1;
    const RenderOutcome c = Render(*direct, scene, one);
    ASSERT_TRUE(c.status.ok()) << c.status.message();
    EXPECT_TRUE(SameBits(a.image.rgba, c.image.rgba));
  }
}

// The same faults through the loader's Linux AIO path (direct reads, stack mode): the render
// ends with an error naming the block, never a hang.
TEST(RenderEngine, AioReadFaultsEndTheRenderNamingTheBlock) {
  TestStore s = BuildGenerated("spheres:30000");
  const std::unique_ptr<store::StoreReader> direct = OpenDirect(s);
  ASSERT_TRUE(direct);
  const render::Scene scene = SpheresScene(*s.reader, render::IntegratorType::kWhitted, 1);
  for (int64_t k : {0, 3, 17}) {
    for (bool corrupt : {false, true}) {
      EngineOptions o = Mode(TraceMode::kStack, Budget(*s.reader, 4));
      (corrupt ? o.faults.corrupt_read : o.faults.fail_read) = k;
      const RenderOutcome r = Render(*direct, scene, o);
      ASSERT_FALSE(r.status.ok()) << "read " << k;
      EXPECT_TRUE(r.stats.aio_reads);
      EXPECT_NE(r.status.message().find("block "), std::string::npos) << r.status.message();
      EXPECT_NE(r.status.message().find(corrupt ? "damaged" : "read failed"), std::string::npos)
          << r.status.message();
    }
  }
}

class Faults : public ::testing::TestWithParam<TraceMode> {};

TEST_P(Faults, ReadErrorEndsTheRenderNamingTheBlock) {
  TestStore s = BuildGenerated("spheres:30000");
  const render::Scene scene = SpheresScene(*s.reader, render::IntegratorType::kWhitted, 1);
  for (int64_t k : {0, 3, 17}) {
    EngineOptions o = Mode(GetParam(), Budget(*s.reader, 4));
    o.faults.fail_read = k;
    const RenderOutcome r = Render(*s.reader, scene, o);
    ASSERT_FALSE(r.status.ok()) << "read " << k;
    EXPECT_NE(r.status.message().find("block "), std::string::npos) << r.status.message();
    EXPECT_NE(r.status.message().find("read failed"), std::string::npos) << r.status.message();
  }
}

TEST_P(Faults, CorruptedBlockEndsTheRenderNamingTheBlock) {
  TestStore s = BuildGenerated("spheres:30000");
  const render::Scene scene = SpheresScene(*s.reader, render::IntegratorType::kWhitted, 1);
  for (int64_t k : {0, 5}) {
    EngineOptions o = Mode(GetParam(), Budget(*s.reader, 4));
    o.faults.corrupt_read = k;
    const RenderOutcome r = Render(*s.reader, scene, o);
    ASSERT_FALSE(r.status.ok()) << "read " << k;
    EXPECT_NE(r.status.message().find("block "), std::string::npos) << r.status.message();
    EXPECT_NE(r.status.message().find("damaged"), std::string::npos) << r.status.message();
  }
}

// After a failed frame the engine's loader and queues are not unwound (blocks claimed, pins
// held): a later frame on it returns the first error at once instead of waiting on them.
TEST_P(Faults, AFailedEngineRendersNoMoreFrames) {
  TestStore s = BuildGenerated("spheres:30000");
  const render::Scene scene = SpheresScene(*s.reader, render::IntegratorType::kWhitted, 1);
  EngineOptions o = Mode(GetParam(), Budget(*s.reader, 4));
  o.faults.fail_read = 3;
  Expected<std::unique_ptr<slave::RenderEngine>> engine = slave::RenderEngine::Create(*s.reader, o);
  ASSERT_TRUE(engine.ok()) << engine.status().message();
  const render::MaterialTable materials = render::MaterialTable::Build(s.reader->materials(), scene);
  const render::Camera camera(scene.cameras[0]);
  std::string first;
  for (int frame = 0; frame < 2; ++frame) {
    render::Film film(camera.width(), camera.height());
    render::FilmSink sink(&film);
    slave::GridTileSource tiles(camera.width(), camera.height(), 16);
    const Status st = (*engine)->RenderFrame(scene, materials, camera, tiles, sink, nullptr);
    ASSERT_FALSE(st.ok()) << "frame " << frame;
    if (frame == 0) first = st.message();
    EXPECT_EQ(st.message(), first) << "frame " << frame;
  }
  EXPECT_NE(first.find("read failed"), std::string::npos) << first;
}

INSTANTIATE_TEST_SUITE_P(Modes, Faults,
                         ::testing::Values(TraceMode::kStack, TraceMode::kSync, TraceMode::kIncore,
                                           TraceMode::kBvh));

}  // namespace
}  // namespace raystack::testing

namespace raystack::testing {
namespace {

// One engine renders frame after frame (the same engine, as for a scene's cameras in turn):
// every frame equals a fresh engine's image, with a cache far smaller than the store (blocks
// are evicted and reloaded across frames) and with one that holds every block (then later
// frames load nothing: the cache stays warm).
TEST(RenderEngine, FramesInSequenceMatchAFreshEngineAndKeepTheCacheWarm) {
  TestStore s = BuildGenerated("spheres:30000");
  render::Scene scene = SpheresScene(*s.reader, render::IntegratorType::kWhitted, 1);
  const render::MaterialTable materials = render::MaterialTable::Build(s.reader->materials(), scene);
  const render::Camera camera(scene.cameras[0]);
  const int all_blocks = static_cast<int>(s.reader->blocks().size());
  for (TraceMode mode : {TraceMode::kStack, TraceMode::kSync}) {
    for (int budget_blocks : {6, all_blocks}) {
      auto engine = slave::RenderEngine::Create(*s.reader, Mode(mode, Budget(*s.reader, budget_blocks)));
      ASSERT_TRUE(engine.ok());
      const RenderOutcome fresh = Render(*s.reader, scene, Mode(mode, Budget(*s.reader, budget_blocks)));
      ASSERT_TRUE(fresh.status.ok()) << fresh.status.message();
      for (int frame = 0; frame < 3; ++frame) {
        render::Film film(camera.width(), camera.height());
        render::FilmSink sink(&film);
        slave::GridTileSource tiles(camera.width(), camera.height(), 16);
        slave::RenderStats stats;
        const Status st = (*engine)->RenderFrame(scene, materials, camera, tiles, sink, &stats);
        ASSERT_TRUE(st.ok()) << "frame " << frame << ": " << st.message();
        EXPECT_TRUE(SameBits(film.Resolve().rgba, fresh.image.rgba)) << "frame " << frame;
        // The ray threads are kept from frame to frame; what they count starts again.
        EXPECT_EQ(stats.rays, fresh.stats.rays) << "frame " << frame;
        EXPECT_EQ(stats.samples, fresh.stats.samples) << "frame " << frame;
        // #U and #C count this frame's loads: a warm frame that loads nothing uses no
        // distinct loaded block, and no frame has more distinct blocks than loads.
        EXPECT_LE(stats.blocks_distinct, stats.blocks_loaded) << "frame " << frame;
        if (frame > 0 && budget_blocks == all_blocks) {
          EXPECT_EQ(stats.blocks_loaded, 0u) << "frame " << frame;
          EXPECT_EQ(stats.blocks_distinct, 0u) << "frame " << frame;
        }
        if (frame > 0 && budget_blocks < all_blocks) {
          EXPECT_GT(stats.blocks_distinct, 0u) << "frame " << frame << ": evicted blocks come back";
        }
      }
    }
  }
}

}  // namespace
}  // namespace raystack::testing
