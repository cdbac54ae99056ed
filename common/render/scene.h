#pragma once
// (placeholder until the scene library lands)
#include <cstdint>
#include <map>
#include <string>
#include <vector>
#include "common/geometry/vec.h"
namespace raystack::render {
struct CameraDesc {
  Vec3f position{0, 0, 1}, look_at{0, 0, 0}, up{0, 1, 0};
  float fov_y_deg = 40;
  int width = 640, height = 480;
};
struct PointLight { Vec3f position; Vec3f intensity; };
enum class MaterialType : uint8_t { kDiffuse, kMirror, kGlass };
struct Material {
  MaterialType type = MaterialType::kDiffuse;
  Vec3f albedo{0.8f, 0.8f, 0.8f};
  float ior = 1.5f;
  Vec3f emission{0, 0, 0};
  bool specular() const { return type != MaterialType::kDiffuse; }
  bool emissive() const { return emission.x > 0 || emission.y > 0 || emission.z > 0; }
};
enum class IntegratorType : uint8_t { kWhitted, kPath };
struct IntegratorDesc { IntegratorType type = IntegratorType::kWhitted; int max_depth = 3; int spp = 1; uint64_t seed = 1; };
struct Scene {
  std::string store;
  std::vector<CameraDesc> cameras;
  std::vector<PointLight> lights;
  Material default_material;
  std::map<std::string, Material> overrides;
  Vec3f background{0, 0, 0};
  IntegratorDesc integrator;
  std::string output = "out.exr";
  std::string source;
};
}  // namespace raystack::render
