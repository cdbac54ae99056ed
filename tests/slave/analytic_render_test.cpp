// Scenes with a known answer: the renderer's radiometry checked against closed forms.

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "tests/slave/render_fixture.h"

namespace raystack::testing {
namespace {

using slave::EngineOptions;
using slave::TraceMode;

EngineOptions Stack() {
  EngineOptions o;
  o.mode = TraceMode::kStack;
  o.threads = 2;
  o.cache_bytes = 64 << 20;
  return o;
}

// A 20 x 20 plane at y = 0 lit by one point light: the radiance of a Lambertian surface is
// albedo / pi * I cos(theta) / d^2 (the inverse-square cosine law), at every pixel.
TEST(AnalyticRender, PointLightOverDiffusePlaneFollowsInverseSquareCosineLaw) {
  TestStore s = BuildObj("v -10 0 -10\nv 10 0 -10\nv 10 0 10\nv -10 0 10\nf 1 2 3\nf 1 3 4\n");
  render::Scene scene;
  render::CameraDesc cam;
  cam.position = {0, 6, 7};
  cam.look_at = {0, 0, 0};
  cam.width = 80;
  cam.height = 60;
  scene.cameras.push_back(cam);
  const Vec3f light{1, 2, -1};
  const float intensity = 25;
  scene.lights.push_back({light, {intensity, intensity, intensity}});
  scene.default_material.albedo = {0.5f, 0.5f, 0.5f};
  const RenderOutcome r = Render(*s.reader, scene, Stack());
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  const render::Camera camera(cam);
  int checked = 0;
  double worst = 0;
  for (int y = 0; y < cam.height; ++y) {
    for (int x = 0; x < cam.width; ++x) {
      const size_t i = static_cast<size_t>(y) * cam.width + x;
      const float z = r.image.z[i];
      if (!std::isfinite(z)) continue;
      const Ray ray = camera.Generate(static_cast<float>(x) + 0.5f, static_cast<float>(y) + 0.5f);
      const Vec3f p = ray.origin + ray.direction * z;
      const Vec3f d = light - p;
      const double d2 = Dot(d, d);
      const double cos_theta = static_cast<double>(d.y) / std::sqrt(d2);
      const double expected = 0.5 / std::numbers::pi * static_cast<double>(intensity) * cos_theta / d2;
      const double got = r.image.rgba[4 * i];
      worst = std::max(worst, std::fabs(got - expected) / expected);
      ++checked;
    }
  }
  EXPECT_GT(checked, cam.width * cam.height / 2);
  EXPECT_LT(worst, 1e-4) << "largest relative error against the closed form";
}

// A closed box seen from inside, every wall emitting Le with albedo a: the radiance everywhere
// is the geometric series Le (1 + a + a^2 + ... + a^D) for paths of at most D bounces.
std::string InwardCube() {
  return "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n"
         "f 1 2 3\nf 1 3 4\nf 5 7 6\nf 5 8 7\nf 1 5 6\nf 1 6 2\nf 4 3 7\nf 4 7 8\n"
         "f 1 4 8\nf 1 8 5\nf 2 6 7\nf 2 7 3\n";
}

render::Scene FurnaceScene(render::IntegratorType type, int depth, int spp) {
  render::Scene scene;
  render::CameraDesc cam;
  cam.position = {0.1f, 0.05f, 0.2f};
  cam.look_at = {0.6f, -0.3f, -1};
  cam.fov_y_deg = 90;
  cam.width = 48;
  cam.height = 48;
  scene.cameras.push_back(cam);
  scene.default_material.albedo = {0.5f, 0.5f, 0.5f};
  scene.default_material.emission = {1, 1, 1};
  scene.integrator.type = type;
  scene.integrator.max_depth = depth;
  scene.integrator.spp = spp;
  scene.integrator.seed = 3;
  return scene;
}

double MeanRed(const image::ImageLayers& image) {
  double sum = 0;
  for (size_t i = 0; i < image.rgba.size(); i += 4) sum += static_cast<double>(image.rgba[i]);
  return sum / static_cast<double>(image.rgba.size() / 4);
}

TEST(AnalyticRender, FurnaceConvergesToTheGeometricSeries) {
  TestStore s = BuildObj(InwardCube());
  // Path tracing with Russian roulette, 64 bounces at most: 2 (1 - 0.5^65) = 2.
  const RenderOutcome path = Render(*s.reader, FurnaceScene(render::IntegratorType::kPath, 64, 16), Stack());
  ASSERT_TRUE(path.status.ok()) << path.status.message();
  // 36864 samples of a variance below 1: the mean's standard error is under 0.3%; allow 1.5%.
  EXPECT_NEAR(MeanRed(path.image), 2.0, 0.03);
  // Two bounces only and no roulette (it starts at the third): exactly 1 + 0.5 + 0.25 per sample.
  const RenderOutcome two = Render(*s.reader, FurnaceScene(render::IntegratorType::kPath, 2, 1), Stack());
  ASSERT_TRUE(two.status.ok());
  for (size_t i = 0; i < two.image.rgba.size(); i += 4) ASSERT_NEAR(two.image.rgba[i], 1.75, 1e-5);
  // Whitted has no diffuse bounces: the walls' own emission only.
  const RenderOutcome whitted = Render(*s.reader, FurnaceScene(render::IntegratorType::kWhitted, 3, 1), Stack());
  ASSERT_TRUE(whitted.status.ok());
  for (size_t i = 0; i < whitted.image.rgba.size(); i += 4) ASSERT_EQ(whitted.image.rgba[i], 1.0f);
  EXPECT_EQ(whitted.stats.rays[static_cast<int>(slave::RayType::kShadow)], 0u);  // no lights
}

// An emitter's edge covering the left quarter of pixel column 32: the column's mean is 0.25 at
// any number of samples. With the first sample through the pixel's centre (outside the
// emitter), 2 samples gave 0.125 and 4 gave 0.19 (found by a rendering researcher): a bias of
// order 1/n at every edge. One sample per pixel still goes through the centre.
TEST(AnalyticRender, AnEdgeCoversItsShareOfAPixelAtAnyNumberOfSamples) {
  // x = 32.25 of a 64-pixel row maps to 0.0078125 at distance 1 (half-width 1: see below).
  TestStore s = BuildObj("v -10 -100 -1\nv 0.0078125 -100 -1\nv 0.0078125 100 -1\nv -10 100 -1\n"
                         "f 1 2 3\nf 1 3 4\n");
  render::Scene scene;
  render::CameraDesc cam;
  cam.position = {0, 0, 0};
  cam.look_at = {0, 0, -1};
  cam.width = 64;
  cam.height = 1024;
  // tan(fov/2) = 16: the image's half-width is 16 * 64 / 1024 = 1 at distance 1.
  cam.fov_y_deg = static_cast<float>(2 * std::atan(16.0) * 180 / std::numbers::pi);
  scene.cameras.push_back(cam);
  scene.default_material.albedo = {0, 0, 0};
  scene.default_material.emission = {1, 1, 1};
  for (const int spp : {1, 2, 4}) {
    SCOPED_TRACE(spp);
    scene.integrator.spp = spp;
    const RenderOutcome r = Render(*s.reader, scene, Stack());
    ASSERT_TRUE(r.status.ok()) << r.status.message();
    double column = 0, left = 0;
    for (int y = 0; y < cam.height; ++y) {
      column += double{r.image.rgba[4 * r.image.PixelIndex(32, y)]};
      left += double{r.image.rgba[4 * r.image.PixelIndex(31, y)]};
    }
    column /= cam.height;
    EXPECT_EQ(left / cam.height, 1.0);  // the column left of it is covered whole
    if (spp == 1) {
      EXPECT_EQ(column, 0.0);  // the centre (x = 32.5) is off the emitter
    } else {
      // 1024 x spp samples of a quarter's chance: standard error <= 0.0096; allow 3 of them.
      EXPECT_NEAR(column, 0.25, 0.029);
    }
  }
}

// A mirror reflects the background scaled by its albedo, and glass lets most of it through.
TEST(AnalyticRender, MirrorReflectsTheBackgroundTimesItsAlbedo) {
  TestStore s = BuildObj("v -10 0 -10\nv 10 0 -10\nv 10 0 10\nv -10 0 10\nf 1 2 3\nf 1 3 4\n");
  render::Scene scene;
  render::CameraDesc cam;
  cam.position = {0, 3, 3};
  cam.look_at = {0, 0, 0};
  cam.width = 32;
  cam.height = 32;
  scene.cameras.push_back(cam);
  scene.background = {0.25f, 0.5f, 1.0f};
  scene.default_material.type = render::MaterialType::kMirror;
  scene.default_material.albedo = {0.8f, 0.8f, 0.8f};
  const RenderOutcome r = Render(*s.reader, scene, Stack());
  ASSERT_TRUE(r.status.ok());
  for (size_t i = 0; i < r.image.z.size(); ++i) {
    if (!std::isfinite(r.image.z[i])) continue;
    EXPECT_FLOAT_EQ(r.image.rgba[4 * i + 0], 0.8f * 0.25f);
    EXPECT_FLOAT_EQ(r.image.rgba[4 * i + 2], 0.8f * 1.0f);
  }
}

}  // namespace
}  // namespace raystack::testing
