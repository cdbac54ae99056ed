// Progressive passes change when samples are computed, never what they are: a frame rendered
// as passes (doubling or fixed, priority or scanline order, stack or sync) is bit for bit the
// frame rendered with every sample of a tile at once. And a stopped plan leaves a valid image.

#include <gtest/gtest.h>

#include "common/render/frame_plan.h"
#include "slave/tile_source.h"
#include "tests/slave/render_fixture.h"

namespace raystack::testing {
namespace {

render::Scene PathScene(const store::StoreReader& store, int spp) {
  render::Scene scene;
  scene.cameras.push_back(FramingCamera(store, 70, 50));
  const Bounds3f b = store.model_bounds();
  scene.lights.push_back({b.upper + (b.upper - b.lower) * 0.5f, {40, 40, 40}});
  scene.background = {0.1f, 0.1f, 0.2f};
  scene.integrator.type = render::IntegratorType::kPath;
  scene.integrator.spp = spp;
  scene.integrator.max_depth = 4;
  scene.integrator.seed = 11;
  return scene;
}

RenderOutcome RenderPlan(const store::StoreReader& store, const render::Scene& scene,
                         slave::EngineOptions options, const render::FramePlan& plan,
                         bool stop_after_first = false) {
  RenderOutcome out;
  Expected<std::unique_ptr<slave::RenderEngine>> engine = slave::RenderEngine::Create(store, options);
  EXPECT_TRUE(engine.ok());
  const render::MaterialTable materials = render::MaterialTable::Build(store.materials(), scene);
  const render::Camera camera(scene.cameras[0]);
  render::Film film(camera.width(), camera.height());
  render::FilmSink sink(&film);
  slave::PlanTileSource tiles(plan);
  if (stop_after_first) tiles.Stop();  // as a stop rule firing at once
  out.status = (*engine)->RenderFrame(scene, materials, camera, tiles, sink, &out.stats);
  out.image = film.Resolve();
  return out;
}

TEST(ProgressiveRender, PassesGiveTheAllAtOnceImageBitForBit) {
  static TestStore s = BuildGenerated("spheres:30000");
  const render::Scene scene = PathScene(*s.reader, 6);
  for (slave::TraceMode mode : {slave::TraceMode::kStack, slave::TraceMode::kSync}) {
    slave::EngineOptions o;
    o.mode = mode;
    o.threads = 2;
    o.result_batch = 64;
    o.cache_bytes = 1 << 20;
    const RenderOutcome whole = Render(*s.reader, scene, o, 16);
    ASSERT_TRUE(whole.status.ok()) << whole.status.message();
    for (render::PixelOrder order : {render::PixelOrder::kPriority, render::PixelOrder::kScanline})
      for (uint32_t pass_spp : {0u, 4u}) {
        SCOPED_TRACE(std::string(slave::TraceModeName(mode)) + " " + render::PixelOrderName(order) +
                     " pass-spp " + std::to_string(pass_spp));
        o.pixel_order = order;
        const render::FramePlan plan = render::MakeFramePlan(70, 50, 16, 6, pass_spp, order);
        const RenderOutcome passes = RenderPlan(*s.reader, scene, o, plan);
        ASSERT_TRUE(passes.status.ok()) << passes.status.message();
        EXPECT_TRUE(SameBits(passes.image.rgba, whole.image.rgba));
        EXPECT_TRUE(SameBits(passes.image.z, whole.image.z));
        EXPECT_TRUE(SameBits(passes.image.variance, whole.image.variance));
        EXPECT_EQ(passes.image.samples, whole.image.samples);
        EXPECT_EQ(passes.stats.samples, 70u * 50u * 6u);
      }
  }
}

TEST(ProgressiveRender, AStoppedPlanEndsWithWhatWasDone) {
  static TestStore s = BuildGenerated("sphere:5000");
  const render::Scene scene = PathScene(*s.reader, 4);
  slave::EngineOptions o;
  o.threads = 2;
  const render::FramePlan plan =
      render::MakeFramePlan(70, 50, 16, 4, 0, render::PixelOrder::kPriority);
  const RenderOutcome out = RenderPlan(*s.reader, scene, o, plan, /*stop_after_first=*/true);
  ASSERT_TRUE(out.status.ok());
  EXPECT_EQ(out.stats.samples, 0u);
  for (uint32_t n : out.image.samples) EXPECT_EQ(n, 0u);
}

}  // namespace
}  // namespace raystack::testing
