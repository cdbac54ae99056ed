#pragma once
// Shared pieces of the renderer tests: a store converted from a generated model or a small
// OBJ written on the spot, a camera framing it, and a one-call render into a Film.

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <memory>
#include <string>

#include "common/base/temp_dir.h"
#include "common/render/camera.h"
#include "common/render/film.h"
#include "common/render/material_table.h"
#include "common/render/scene.h"
#include "common/store/store_reader.h"
#include "slave/render_engine.h"
#include "tools/prep/convert.h"
#include "tests/support/test_dir.h"

namespace raystack::testing {

struct TestStore {
  std::unique_ptr<TempDir> dir;
  std::unique_ptr<store::StoreReader> reader;
};

inline TestStore BuildStore(prep::ConvertOptions o, uint32_t target_kb = 8) {
  TestStore s;
  s.dir = raystack::testing::MakeTestDir();
  EXPECT_TRUE(s.dir);
  o.output = s.dir->path() + "/store";
  o.target_block_bytes = target_kb * 1024;
  o.max_block_bytes = std::max<uint32_t>(4 * target_kb, 32) * 1024;
  o.quiet = true;
  o.threads = 2;
  Expected<prep::ConvertReport> report = prep::Convert(o);
  EXPECT_TRUE(report.ok()) << report.status().message();
  Expected<std::unique_ptr<store::StoreReader>> reader = store::StoreReader::Open(o.output);
  EXPECT_TRUE(reader.ok()) << reader.status().message();
  s.reader = std::move(*reader);
  return s;
}

inline TestStore BuildGenerated(const std::string& spec, uint32_t target_kb = 8) {
  prep::ConvertOptions o;
  o.generate = spec;
  return BuildStore(o, target_kb);
}

// A second reader of `s`'s store that reads blocks.bin past the page cache (--direct-io on);
// null, with a test failure, when the filesystem refuses.
inline std::unique_ptr<store::StoreReader> OpenDirect(const TestStore& s) {
  Expected<std::unique_ptr<store::StoreReader>> direct = store::StoreReader::Open(s.reader->dir());
  EXPECT_TRUE(direct.ok()) << direct.status().message();
  if (!direct.ok()) return nullptr;
  const Status d = (*direct)->UseDirectReads();
  EXPECT_TRUE(d.ok()) << d.message();
  if (!d.ok()) return nullptr;
  return std::move(*direct);
}

// A store from OBJ text (written to a temp file first), with `mtl_text` as model.mtl beside it
// when given (the OBJ names it with "mtllib model.mtl").
inline TestStore BuildObj(const std::string& obj_text, uint32_t target_kb = 8,
                          const std::string& mtl_text = "") {
  Expected<TempDir> tmp = TempDir::Create();
  EXPECT_TRUE(tmp.ok());
  const std::string path = tmp->File("model.obj");
  std::ofstream(path) << obj_text;
  if (!mtl_text.empty()) std::ofstream(tmp->File("model.mtl")) << mtl_text;
  prep::ConvertOptions o;
  o.inputs = {path};
  TestStore s = BuildStore(o, target_kb);
  return s;
}

// A camera outside the model's bounds, looking at their centre.
inline render::CameraDesc FramingCamera(const store::StoreReader& store, int w, int h) {
  const Bounds3f b = store.model_bounds();
  const Vec3f c = (b.lower + b.upper) * 0.5f;
  const Vec3f e = b.upper - b.lower;
  const float r = 0.5f * Length(e);
  render::CameraDesc cam;
  cam.look_at = c;
  cam.position = c + Normalize(Vec3f{0.6f, 0.7f, 1.0f}) * (2.2f * r);
  cam.fov_y_deg = 45;
  cam.width = w;
  cam.height = h;
  return cam;
}

struct RenderOutcome {
  Status status;
  image::ImageLayers image;
  slave::RenderStats stats;
  uint64_t nonfinite_dropped = 0;  // samples the film refused (NaN or Inf radiance)
};

inline RenderOutcome Render(const store::StoreReader& store, const render::Scene& scene,
                            slave::EngineOptions options, int tile = 16) {
  RenderOutcome out;
  Expected<std::unique_ptr<slave::RenderEngine>> engine = slave::RenderEngine::Create(store, options);
  if (!engine.ok()) {
    out.status = engine.status();
    return out;
  }
  const render::MaterialTable materials = render::MaterialTable::Build(store.materials(), scene);
  const render::Camera camera(scene.cameras[0]);
  render::Film film(camera.width(), camera.height());
  render::FilmSink sink(&film);
  slave::GridTileSource tiles(camera.width(), camera.height(), tile);
  out.status = (*engine)->RenderFrame(scene, materials, camera, tiles, sink, &out.stats);
  out.image = film.Resolve();
  out.nonfinite_dropped = film.nonfinite_dropped();
  return out;
}

// Bytes of a float array, for bit-exact comparisons that also treat NaN == NaN.
inline bool SameBits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

}  // namespace raystack::testing
