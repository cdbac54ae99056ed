// libFuzzer target: the scene file parser (JSON, then every field validated). A scene it
// accepts must hold only values inside the documented ranges: those are checked here, so a
// validation gap shows up as a crash.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "common/base/check.h"
#include "common/geometry/float_range.h"
#include "common/render/scene.h"
#include "tests/fuzz/fuzz_quiet.h"

namespace {

bool Finite(raystack::Vec3f v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

// A point within the range float ray tracing is sound in (common/geometry/float_range.h).
bool InRange(raystack::Vec3f v) {
  return std::fabs(v.x) <= raystack::kMaxCoordinate && std::fabs(v.y) <= raystack::kMaxCoordinate &&
         std::fabs(v.z) <= raystack::kMaxCoordinate;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace raystack::render;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  raystack::Expected<Scene> scene = ParseScene(text, "fuzz.json", "/base");
  if (!scene.ok()) {
    CHECK(!scene.status().message().empty());
    return 0;
  }
  CHECK(!scene->cameras.empty());
  for (const CameraDesc& c : scene->cameras) {
    CHECK(c.width >= 1 && c.width <= kMaxImageSide && c.height >= 1 && c.height <= kMaxImageSide);
    CHECK(c.fov_y_deg > 0 && c.fov_y_deg < 180);
    CHECK(InRange(c.position) && InRange(c.look_at) && Finite(c.up));
  }
  for (const PointLight& l : scene->lights) CHECK(InRange(l.position) && Finite(l.intensity));
  CHECK(scene->integrator.spp >= 1 && scene->integrator.spp <= kMaxSpp);
  CHECK(scene->integrator.max_depth >= 0 && scene->integrator.max_depth <= kMaxDepth);
  CHECK(Finite(scene->background));
  return 0;
}
