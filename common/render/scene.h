#pragma once
// The scene description a render job starts from: which store to render, the cameras, lights,
// material overrides and integrator settings, read from a JSON file (SCENE_FORMAT.md beside
// this header is the prose spec). Everything here is validated once at load time, so the
// engine can trust every field: a bad file ends with a Status naming the file and the JSON path
// of the offending value (e.g. "scene.json: camera.fov_y_deg: must be in (0, 180), got 190").

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "common/base/status.h"
#include "common/geometry/vec.h"

namespace raystack::render {

struct CameraDesc {
  Vec3f position{0, 0, 1}, look_at{0, 0, 0}, up{0, 1, 0};
  float fov_y_deg = 40;
  int width = 640, height = 480;
};

struct PointLight {
  Vec3f position;
  Vec3f intensity;  // radiant intensity (W/sr), per channel
};

enum class MaterialType : uint8_t { kDiffuse, kMirror, kGlass };

struct Material {
  MaterialType type = MaterialType::kDiffuse;
  Vec3f albedo{0.8f, 0.8f, 0.8f};  // diffuse reflectance; mirror reflectance; glass tint
  float ior = 1.5f;                // glass only
  Vec3f emission{0, 0, 0};         // emitted radiance, any type may emit
  bool specular() const { return type != MaterialType::kDiffuse; }
  bool emissive() const { return emission.x > 0 || emission.y > 0 || emission.z > 0; }
};

enum class IntegratorType : uint8_t { kWhitted, kPath };

struct IntegratorDesc {
  IntegratorType type = IntegratorType::kWhitted;
  int max_depth = 3;
  int spp = 1;
  uint64_t seed = 1;
  // "animated_seed": each frame's random numbers from the seed and the frame's index, so a moving
  // camera's noise moves too instead of staying on the screen (an animator saw the grain of a
  // turntable stand still while the model slid under it). Off: a camera repeated gives the same
  // image, and a still camera's noise does not flicker.
  bool animated_seed = false;
  // The seed frame `frame` renders with.
  uint64_t SeedOfFrame(size_t frame) const;
};

struct Scene;
// The scene frame `frame` renders: `scene` itself, or a copy in `copy` with the frame's seed
// (IntegratorDesc::animated_seed).
const Scene& SceneOfFrame(const Scene& scene, size_t frame, Scene* copy);

struct Scene {
  std::string store;                // resolved against the scene file's folder
  std::vector<CameraDesc> cameras;  // "camera": {...} or "cameras": [{...}, ...]; at least one
  std::vector<PointLight> lights;
  Material default_material;  // "materials": {"default": {...}} (else the default above)
  bool default_given = false;  // "default" was in "materials"
  std::map<std::string, Material> overrides;  // "materials": {"<MTL name>": {...}}
  Vec3f background{0, 0, 0};  // radiance of rays that escape ("background": [r,g,b])
  IntegratorDesc integrator;
  std::string output = "out.exr";  // resolved against the scene file's folder
  std::string source;              // the scene file path, for messages
};

// Limits the loader enforces (also the documented ranges of SCENE_FORMAT.md).
inline constexpr int kMaxImageSide = 16384;
inline constexpr int kMaxSpp = 65535;
inline constexpr int kMaxDepth = 64;
// Whitted traces a shadow ray from every hit to every point light, all of a hit's at once: a
// scene of 100,000 lights took 5.4 GB for a 32 x 32 image and grew past 12 GB at 640 x 480 (a
// hostile-input review). The path integrator picks one light a hit and takes any number.
inline constexpr size_t kMaxWhittedLights = 1024;
inline constexpr float kMinIor = 1.0f, kMaxIor = 4.0f;
inline constexpr size_t kMaxSceneFileBytes = size_t{16} << 20;  // a scene is a few KB
inline constexpr int kMaxJsonNesting = 64;  // the format needs 4; deeper input is hostile

// Reads and validates the scene file at `path`; relative "store" and "output" paths are
// resolved against the file's folder. Errors name `path`. Warnings (albedo above 1, "ior" on a
// material that is not glass) are logged, not returned.
Expected<Scene> LoadScene(const std::string& path);

// The same from text already in memory: `source_name` is what messages call the file (it
// becomes Scene::source) and `base_dir` is the folder relative paths are resolved against
// (empty: left as written).
Expected<Scene> ParseScene(std::string_view json_text, const std::string& source_name,
                           const std::string& base_dir);

// The type names the format uses ("diffuse", "mirror", "glass"; "whitted", "path"), for
// messages and logs.
const char* MaterialTypeName(MaterialType type);
const char* IntegratorTypeName(IntegratorType type);

}  // namespace raystack::render
