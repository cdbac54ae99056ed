#include "common/render/scene.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <limits>
#include <new>
#include <nlohmann/json.hpp>
#include <set>
#include <utility>

#include "common/base/log.h"
#include "common/geometry/float_range.h"
#include "common/render/random.h"

namespace raystack::render {
namespace {

// A key that is a comment: "//", "// the key light", "//2".
bool IsComment(const std::string& key) { return key.rfind("//", 0) == 0; }

using Json = nlohmann::json;
namespace fs = std::filesystem;

constexpr const char* kComponent = "scene";

bool IsIdentifier(std::string_view key) {
  if (key.empty()) return false;
  for (char c : key) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '_' || c == '-';
    if (!ok) return false;
  }
  return true;
}

// JSON paths as messages print them: "camera.fov_y_deg", "lights[2].intensity",
// "materials[\"red glass\"].ior" (keys that are not plain words are quoted).
std::string Child(const std::string& path, std::string_view key) {
  if (IsIdentifier(key)) return path.empty() ? std::string(key) : path + "." + std::string(key);
  return path + "[" + Json(std::string(key)).dump(-1, ' ', false, Json::error_handler_t::replace) +
         "]";
}
std::string Index(const std::string& path, size_t i) {
  return path + "[" + std::to_string(i) + "]";
}

// A value as it appears in a message: short, so a huge array does not flood the terminal.
std::string Show(const Json& v) {
  std::string text = v.dump(-1, ' ', false, Json::error_handler_t::replace);
  if (text.size() > 48) text = text.substr(0, 45) + "...";
  return text;
}
std::string Show(Vec3f v) {
  return StrFormat("[%g, %g, %g]", double{v.x}, double{v.y}, double{v.z});
}

std::string JoinKeys(std::initializer_list<const char*> keys) {
  std::string out;
  for (const char* k : keys) out += (out.empty() ? "" : ", ") + std::string(k);
  return out;
}

// 1-based line and column of the 0-based byte `offset` of `text`.
std::string LineColumn(std::string_view text, size_t offset) {
  offset = std::min(offset, text.size());
  size_t line = 1, line_start = 0;
  for (size_t i = 0; i < offset; ++i) {
    if (text[i] == '\n') {
      ++line;
      line_start = i + 1;
    }
  }
  return std::to_string(line) + ":" + std::to_string(offset - line_start + 1);
}

// Raised by the parse callback (inside this file only; ParseScene turns it into a Status).
struct StructureError {
  std::string path;
  std::string what;
};

// A first pass over the text (nlohmann's SAX interface: nothing is built) that rejects nesting
// deeper than the format could need, so hostile input costs nothing, and duplicate keys, which
// nlohmann would otherwise resolve silently by keeping the last one. Not the DOM parser's
// callback: at every object's end that scans the whole parent, quadratic in the siblings (a
// scene of 40,000 empty materials took 8 s to parse). Syntax errors stop it quietly; the DOM
// parse that follows reports them with their place.
class StructureGuard final : public nlohmann::json_sax<Json> {
 public:
  bool null() override { return ElementDone(); }
  bool boolean(bool) override { return ElementDone(); }
  bool number_integer(number_integer_t) override { return ElementDone(); }
  bool number_unsigned(number_unsigned_t) override { return ElementDone(); }
  bool number_float(number_float_t, const string_t&) override { return ElementDone(); }
  bool string(string_t&) override { return ElementDone(); }
  bool binary(binary_t&) override { return ElementDone(); }
  bool start_object(std::size_t) override { return Open(false); }
  bool start_array(std::size_t) override { return Open(true); }
  bool end_object() override { return Close(); }
  bool end_array() override { return Close(); }
  bool key(string_t& key) override {
    if (frames_.empty()) return true;
    Frame& top = frames_.back();
    top.key = key;
    if (!top.keys.insert(top.key).second)
      throw StructureError{Path(), "duplicate key (each key may appear once in an object)"};
    return true;
  }
  bool parse_error(std::size_t, const std::string&, const nlohmann::detail::exception&) override {
    return false;
  }

 private:
  struct Frame {
    bool array;
    size_t count;     // arrays: elements finished so far, i.e. the index of the current one
    std::string key;  // objects: the current key
    std::set<std::string> keys;
  };
  bool Open(bool array) {
    if (frames_.size() >= static_cast<size_t>(kMaxJsonNesting))
      throw StructureError{Path(), StrFormat("nested deeper than %d levels", kMaxJsonNesting)};
    frames_.push_back(Frame{array, 0, {}, {}});
    return true;
  }
  bool Close() {
    if (!frames_.empty()) frames_.pop_back();
    return ElementDone();
  }
  bool ElementDone() {
    if (!frames_.empty() && frames_.back().array) ++frames_.back().count;
    return true;
  }
  std::string Path() const {
    std::string path;
    for (const Frame& f : frames_) path = f.array ? Index(path, f.count) : Child(path, f.key);
    return path;
  }
  std::vector<Frame> frames_;
};

class SceneParser {
 public:
  SceneParser(std::string source, std::string base_dir)
      : source_(std::move(source)), base_dir_(std::move(base_dir)) {}

  Status Parse(const Json& root, Scene* scene) {
    scene->source = source_;
    if (!root.is_object())
      return Error("", "the top level must be a JSON object, got " + std::string(root.type_name()));
    RAYSTACK_RETURN_IF_ERROR(CheckKeys(root, "",
                                       {"store", "camera", "cameras", "lights", "materials",
                                        "background", "integrator", "output"}));

    if (!root.contains("store")) return Error("store", "required key missing");
    RAYSTACK_RETURN_IF_ERROR(ReadPath(root["store"], "store", &scene->store));

    const bool has_camera = root.contains("camera"), has_cameras = root.contains("cameras");
    if (has_camera && has_cameras)
      return Error("cameras", "give \"camera\" (one) or \"cameras\" (a list), not both");
    if (!has_camera && !has_cameras)
      return Error("camera", "required key missing (or \"cameras\": a list of cameras)");
    if (has_camera) {
      scene->cameras.emplace_back();
      RAYSTACK_RETURN_IF_ERROR(ReadCamera(root["camera"], "camera", &scene->cameras.back()));
    } else {
      const Json& list = root["cameras"];
      if (!list.is_array() || list.empty())
        return Error("cameras", "must be a non-empty array of cameras, got " + Show(list));
      scene->cameras.resize(list.size());
      for (size_t i = 0; i < list.size(); ++i)
        RAYSTACK_RETURN_IF_ERROR(ReadCamera(list[i], Index("cameras", i), &scene->cameras[i]));
    }

    if (root.contains("lights")) {
      const Json& list = root["lights"];
      if (!list.is_array()) return Error("lights", "must be an array of lights, got " + Show(list));
      scene->lights.resize(list.size());
      for (size_t i = 0; i < list.size(); ++i)
        RAYSTACK_RETURN_IF_ERROR(ReadLight(list[i], Index("lights", i), &scene->lights[i]));
    }

    if (root.contains("materials")) {
      const Json& table = root["materials"];
      if (!table.is_object())
        return Error("materials", "must be an object of materials by name, got " + Show(table));
      for (const auto& [name, value] : table.items()) {
        if (IsComment(name)) continue;
        const std::string path = Child("materials", name);
        if (name.empty()) return Error(path, "a material name must not be empty");
        Material* material = name == "default" ? &scene->default_material : &scene->overrides[name];
        if (name == "default") scene->default_given = true;
        RAYSTACK_RETURN_IF_ERROR(ReadMaterial(value, path, material));
      }
    }

    if (root.contains("background")) {
      RAYSTACK_RETURN_IF_ERROR(ReadVec3(root["background"], "background", &scene->background));
      RAYSTACK_RETURN_IF_ERROR(CheckNonNegative(scene->background, "background"));
    }
    if (root.contains("integrator"))
      RAYSTACK_RETURN_IF_ERROR(
          ReadIntegrator(root["integrator"], "integrator", &scene->integrator));
    if (scene->integrator.type == IntegratorType::kWhitted && scene->lights.size() > kMaxWhittedLights)
      return Error("lights", StrFormat("%zu point lights: the whitted integrator traces a shadow "
                                       "ray from every hit to each, and takes at most %zu (the "
                                       "path integrator picks one a hit, and takes any number)",
                                       scene->lights.size(), kMaxWhittedLights));
    if (root.contains("output"))
      RAYSTACK_RETURN_IF_ERROR(ReadPath(root["output"], "output", &scene->output));
    else
      scene->output = Resolve(scene->output);
    return OkStatus();
  }

 private:
  Status Error(const std::string& path, const std::string& what) const {
    return Status::Error(source_ + ": " + (path.empty() ? "" : path + ": ") + what);
  }
  void Warn(const std::string& path, const std::string& what) const {
    LOG_WARNING(kComponent, "%s: %s: %s", source_.c_str(), path.c_str(), what.c_str());
  }
  Status TypeError(const std::string& path, const char* expected, const Json& v) const {
    // "got null", not "got null null": a null shows as its type alone.
    const std::string got = v.is_null() ? "null" : std::string(v.type_name()) + " " + Show(v);
    return Error(path, std::string("must be ") + expected + ", got " + got);
  }

  // Unknown keys are errors: a misspelt key ("fov_y") must not silently leave a default. Keys
  // that start with "//" are comments (JSON has none; a scene author could not annotate a scene).
  Status CheckKeys(const Json& v, const std::string& path,
                   std::initializer_list<const char*> allowed) const {
    if (!v.is_object()) return TypeError(path, "an object", v);
    for (const auto& item : v.items()) {
      if (IsComment(item.key())) continue;
      bool known = false;
      for (const char* k : allowed) known = known || item.key() == k;
      if (!known)
        return Error(Child(path, item.key()),
                     "unknown key (expected one of: " + JoinKeys(allowed) + ")");
    }
    return OkStatus();
  }

  Status ReadFloat(const Json& v, const std::string& path, float* out) const {
    if (!v.is_number()) return TypeError(path, "a number", v);
    const double d = v.get<double>();
    if (!std::isfinite(d) || std::fabs(d) > double{std::numeric_limits<float>::max()})
      return Error(path, "must be a finite number in float range, got " + Show(v));
    *out = static_cast<float>(d);
    return OkStatus();
  }

  // An integer in [lo, hi]; 640.0 is accepted as 640, 640.5 is not.
  Status ReadInt(const Json& v, const std::string& path, int64_t lo, int64_t hi,
                 int64_t* out) const {
    if (!v.is_number()) return TypeError(path, "an integer", v);
    const std::string range = StrFormat("must be in [%lld, %lld], got ", static_cast<long long>(lo),
                                        static_cast<long long>(hi));
    if (v.is_number_float()) {
      const double d = v.get<double>();
      if (!std::isfinite(d) || d != std::floor(d))
        return Error(path, "must be an integer, got " + Show(v));
      if (d < static_cast<double>(lo) || d > static_cast<double>(hi))
        return Error(path, range + Show(v));
      *out = static_cast<int64_t>(d);
    } else if (v.is_number_unsigned()) {
      const uint64_t u = v.get<uint64_t>();  // nlohmann's type for every integer >= 0
      if (u > static_cast<uint64_t>(hi) || static_cast<int64_t>(u) < lo)
        return Error(path, range + Show(v));
      *out = static_cast<int64_t>(u);
    } else {
      const int64_t i = v.get<int64_t>();
      if (i < lo || i > hi) return Error(path, range + Show(v));
      *out = i;
    }
    return OkStatus();
  }
  Status ReadInt(const Json& v, const std::string& path, int lo, int hi, int* out) const {
    int64_t value = 0;
    RAYSTACK_RETURN_IF_ERROR(ReadInt(v, path, int64_t{lo}, int64_t{hi}, &value));
    *out = static_cast<int>(value);
    return OkStatus();
  }

  Status ReadVec3(const Json& v, const std::string& path, Vec3f* out) const {
    if (!v.is_array() || v.size() != 3)
      return Error(path, "must be an array of 3 numbers, got " + Show(v));
    for (int k = 0; k < 3; ++k)
      RAYSTACK_RETURN_IF_ERROR(
          ReadFloat(v[static_cast<size_t>(k)], Index(path, static_cast<size_t>(k)), &(*out)[k]));
    return OkStatus();
  }

  // A point of the scene: within the range float ray tracing is sound in (float_range.h).
  Status ReadPosition(const Json& v, const std::string& path, Vec3f* out) const {
    RAYSTACK_RETURN_IF_ERROR(ReadVec3(v, path, out));
    for (int k = 0; k < 3; ++k)
      if (std::fabs((*out)[k]) > kMaxCoordinate)
        return Error(path, "must be within +-1e18 (float ray tracing overflows beyond; scale the "
                           "scene down), got " + Show(v));
    return OkStatus();
  }

  Status CheckNonNegative(Vec3f v, const std::string& path) const {
    if (v.x < 0 || v.y < 0 || v.z < 0) return Error(path, "must not be negative, got " + Show(v));
    return OkStatus();
  }

  std::string Resolve(const std::string& p) const {
    if (base_dir_.empty() || fs::path(p).is_absolute()) return p;
    return (fs::path(base_dir_) / p).lexically_normal().string();
  }

  Status ReadPath(const Json& v, const std::string& path, std::string* out) const {
    if (!v.is_string()) return TypeError(path, "a string (a path)", v);
    const std::string& text = v.get_ref<const std::string&>();
    if (text.empty()) return Error(path, "must not be empty");
    // The system cuts a path at its first NUL: "out\u0000.exr" would be written as "out".
    if (text.find('\0') != std::string::npos) return Error(path, "must not contain a NUL (\\u0000)");
    *out = Resolve(text);
    return OkStatus();
  }

  Status ReadCamera(const Json& v, const std::string& path, CameraDesc* camera) const {
    RAYSTACK_RETURN_IF_ERROR(
        CheckKeys(v, path, {"position", "look_at", "up", "fov_y_deg", "width", "height"}));
    if (v.contains("position"))
      RAYSTACK_RETURN_IF_ERROR(ReadPosition(v["position"], Child(path, "position"), &camera->position));
    if (v.contains("look_at"))
      RAYSTACK_RETURN_IF_ERROR(ReadPosition(v["look_at"], Child(path, "look_at"), &camera->look_at));
    if (v.contains("up"))
      RAYSTACK_RETURN_IF_ERROR(ReadVec3(v["up"], Child(path, "up"), &camera->up));
    if (v.contains("fov_y_deg")) {
      const std::string fov_path = Child(path, "fov_y_deg");
      RAYSTACK_RETURN_IF_ERROR(ReadFloat(v["fov_y_deg"], fov_path, &camera->fov_y_deg));
      if (!(camera->fov_y_deg > 0 && camera->fov_y_deg < 180))
        return Error(fov_path, "must be in (0, 180), got " + Show(v["fov_y_deg"]) +
                                   (camera->fov_y_deg == 180 ? " (180 as a float)" : ""));
    }
    if (v.contains("width"))
      RAYSTACK_RETURN_IF_ERROR(
          ReadInt(v["width"], Child(path, "width"), 1, kMaxImageSide, &camera->width));
    if (v.contains("height"))
      RAYSTACK_RETURN_IF_ERROR(
          ReadInt(v["height"], Child(path, "height"), 1, kMaxImageSide, &camera->height));

    // The same test in double the Camera makes: no basis, no image.
    const double dx = double{camera->look_at.x} - double{camera->position.x};
    const double dy = double{camera->look_at.y} - double{camera->position.y};
    const double dz = double{camera->look_at.z} - double{camera->position.z};
    const double d_len = std::sqrt(dx * dx + dy * dy + dz * dz);
    if (d_len == 0)
      return Error(Child(path, "look_at"), "equals position " + Show(camera->position) +
                                               ": the camera has no view direction");
    const double ux = camera->up.x, uy = camera->up.y, uz = camera->up.z;
    const double u_len = std::sqrt(ux * ux + uy * uy + uz * uz);
    const double cx = dy * uz - dz * uy, cy = dz * ux - dx * uz, cz = dx * uy - dy * ux;
    const double sin_angle =
        u_len == 0 ? 0 : std::sqrt(cx * cx + cy * cy + cz * cz) / (d_len * u_len);
    if (!(sin_angle > kMinUpSine))
      return Error(Child(path, "up"), Show(camera->up) +
                                          " is zero or parallel to the view direction "
                                          "(look_at - position): the image has no 'up'");
    return OkStatus();
  }

  Status ReadLight(const Json& v, const std::string& path, PointLight* light) const {
    RAYSTACK_RETURN_IF_ERROR(CheckKeys(v, path, {"type", "position", "intensity"}));
    if (v.contains("type")) {
      const Json& type = v["type"];
      if (!type.is_string()) return TypeError(Child(path, "type"), "a string", type);
      if (type.get_ref<const std::string&>() != "point")
        return Error(Child(path, "type"),
                     "unknown light type " + Show(type) + " (expected: point)");
    }
    for (const char* key : {"position", "intensity"})
      if (!v.contains(key)) return Error(Child(path, key), "required key missing");
    RAYSTACK_RETURN_IF_ERROR(ReadPosition(v["position"], Child(path, "position"), &light->position));
    RAYSTACK_RETURN_IF_ERROR(ReadVec3(v["intensity"], Child(path, "intensity"), &light->intensity));
    return CheckNonNegative(light->intensity, Child(path, "intensity"));
  }

  Status ReadMaterial(const Json& v, const std::string& path, Material* material) const {
    RAYSTACK_RETURN_IF_ERROR(CheckKeys(v, path, {"type", "albedo", "ior", "emission", "radiance"}));
    *material = Material{};
    bool emissive_type = false;
    if (v.contains("type")) {
      const Json& type = v["type"];
      if (!type.is_string()) return TypeError(Child(path, "type"), "a string", type);
      const std::string& name = type.get_ref<const std::string&>();
      if (name == "diffuse") {
        material->type = MaterialType::kDiffuse;
      } else if (name == "mirror") {
        material->type = MaterialType::kMirror;
        material->albedo = {1, 1, 1};
      } else if (name == "glass") {
        material->type = MaterialType::kGlass;
        material->albedo = {1, 1, 1};
      } else if (name == "emissive") {
        material->type = MaterialType::kDiffuse;
        material->albedo = {0, 0, 0};
        emissive_type = true;
      } else {
        return Error(Child(path, "type"), "unknown material type " + Show(type) +
                                              " (expected: diffuse, mirror, glass, emissive)");
      }
    }
    if (v.contains("albedo")) {
      const std::string albedo_path = Child(path, "albedo");
      RAYSTACK_RETURN_IF_ERROR(ReadVec3(v["albedo"], albedo_path, &material->albedo));
      RAYSTACK_RETURN_IF_ERROR(CheckNonNegative(material->albedo, albedo_path));
      const Vec3f a = material->albedo;
      if (a.x > 1 || a.y > 1 || a.z > 1)
        Warn(albedo_path,
             Show(a) + " is above 1: the surface reflects more light than it receives");
    }
    if (v.contains("ior")) {
      const std::string ior_path = Child(path, "ior");
      RAYSTACK_RETURN_IF_ERROR(ReadFloat(v["ior"], ior_path, &material->ior));
      if (!(material->ior >= kMinIor && material->ior <= kMaxIor))
        return Error(ior_path, "must be in [1, 4], got " + Show(v["ior"]));
      if (material->type != MaterialType::kGlass) Warn(ior_path, "ignored: only glass refracts");
    }
    if (v.contains("emission") && v.contains("radiance"))
      return Error(Child(path, "radiance"),
                   "give \"emission\" or its alias \"radiance\", not both");
    const char* emission_key = v.contains("radiance") ? "radiance" : "emission";
    if (v.contains(emission_key)) {
      const std::string emission_path = Child(path, emission_key);
      RAYSTACK_RETURN_IF_ERROR(ReadVec3(v[emission_key], emission_path, &material->emission));
      RAYSTACK_RETURN_IF_ERROR(CheckNonNegative(material->emission, emission_path));
    } else if (emissive_type) {
      return Error(Child(path, "emission"), "required key missing (an emissive material needs it)");
    }
    return OkStatus();
  }

  Status ReadIntegrator(const Json& v, const std::string& path, IntegratorDesc* integrator) const {
    RAYSTACK_RETURN_IF_ERROR(
        CheckKeys(v, path, {"type", "max_depth", "spp", "seed", "animated_seed"}));
    if (v.contains("type")) {
      const Json& type = v["type"];
      if (!type.is_string()) return TypeError(Child(path, "type"), "a string", type);
      const std::string& name = type.get_ref<const std::string&>();
      if (name == "whitted") {
        integrator->type = IntegratorType::kWhitted;
      } else if (name == "path") {
        integrator->type = IntegratorType::kPath;
      } else {
        return Error(Child(path, "type"),
                     "unknown integrator type " + Show(type) + " (expected: whitted, path)");
      }
    }
    if (v.contains("max_depth"))
      RAYSTACK_RETURN_IF_ERROR(
          ReadInt(v["max_depth"], Child(path, "max_depth"), 0, kMaxDepth, &integrator->max_depth));
    if (v.contains("spp"))
      RAYSTACK_RETURN_IF_ERROR(ReadInt(v["spp"], Child(path, "spp"), 1, kMaxSpp, &integrator->spp));
    if (v.contains("seed")) {
      const Json& seed = v["seed"];
      // 7.0 and 1e3 as the other integer keys take them (a researcher's 7.0 was refused), up
      // to 2^53, where a float still names one integer.
      // (Below 2^53: 9007199254740993.0 reads as 2^53, another seed.)
      const bool whole_float = seed.is_number_float() && std::trunc(seed.get<double>()) == seed.get<double>() &&
                               seed.get<double>() >= 0 && seed.get<double>() < 9007199254740992.0;
      if (!seed.is_number_unsigned() && !whole_float)
        return Error(Child(path, "seed"), "must be an integer in [0, 2^64), got " +
                                              std::string(seed.type_name()) + " " + Show(seed) +
                                              (seed.is_number_float() && seed.get<double>() >= 0
                                                   ? " (from 2^53 on, write it as an integer: digits, no exponent or point)"
                                                   : ""));
      integrator->seed = whole_float ? static_cast<uint64_t>(seed.get<double>()) : seed.get<uint64_t>();
    }
    if (v.contains("animated_seed")) {
      const Json& animated = v["animated_seed"];
      if (!animated.is_boolean())
        return TypeError(Child(path, "animated_seed"), "true or false", animated);
      integrator->animated_seed = animated.get<bool>();
    }
    return OkStatus();
  }

  // Below this sine between up and the view direction (0.00006 degrees) the image's 'up' is
  // numerically meaningless.
  static constexpr double kMinUpSine = 1e-6;

  std::string source_;
  std::string base_dir_;
};

// nlohmann's messages start "[json.exception.parse_error.101] parse error at line 2, column 5: ";
// we give the place ourselves, so keep only what follows.
std::string Detail(const char* what) {
  std::string text = what;
  size_t pos = text.find("] ");
  if (pos != std::string::npos) text = text.substr(pos + 2);
  if (text.rfind("parse error", 0) == 0) {
    pos = text.find(": ");
    if (pos != std::string::npos) text = text.substr(pos + 2);
  }
  return text;
}

// The likely slip behind the parser's words, for the mistakes people make writing JSON by
// hand (a user read "unexpected '}'; expected string literal" without seeing the comma), from
// the parser's words and the text around the place (`at`: the offending character).
std::string SlipHint(const std::string& detail, std::string_view text, size_t at) {
  auto has = [&](const char* words) { return detail.find(words) != std::string::npos; };
  size_t before = std::min(at, text.size());
  while (before > 0 && std::isspace(static_cast<unsigned char>(text[before - 1]))) --before;
  const char previous = before > 0 ? text[before - 1] : '\0';
  const char here = at < text.size() ? text[at] : '\0';
  if (here == '\'') return " (JSON strings take double quotes, not single)";
  if (previous == ',' && (has("unexpected '}'") || has("unexpected ']'")))
    return StrFormat(" (a comma after the last %s? JSON allows none before '%c')",
                     here == '}' ? "member" : "item", here);
  if (has("parsing object - unexpected string literal"))
    return " (a comma missing before this member?)";
  if (has("parsing array - unexpected") && !has("unexpected '}'") && !has("unexpected end"))
    return " (a comma missing before this item?)";
  return "";
}

}  // namespace

uint64_t IntegratorDesc::SeedOfFrame(size_t frame) const {
  if (!animated_seed) return seed;
  return MixBits(seed ^ MixBits(uint64_t{frame} + 0x6a09e667f3bcc909ull));
}

const Scene& SceneOfFrame(const Scene& scene, size_t frame, Scene* copy) {
  if (!scene.integrator.animated_seed) return scene;
  *copy = scene;
  copy->integrator.seed = scene.integrator.SeedOfFrame(frame);
  copy->integrator.animated_seed = false;  // (the seed is the frame's now)
  return *copy;
}

const char* MaterialTypeName(MaterialType type) {
  switch (type) {
    case MaterialType::kDiffuse: return "diffuse";
    case MaterialType::kMirror: return "mirror";
    case MaterialType::kGlass: return "glass";
  }
  return "?";
}

const char* IntegratorTypeName(IntegratorType type) {
  switch (type) {
    case IntegratorType::kWhitted: return "whitted";
    case IntegratorType::kPath: return "path";
  }
  return "?";
}

Expected<Scene> ParseScene(std::string_view json_text, const std::string& source_name,
                           const std::string& base_dir) {
  if (json_text.size() > kMaxSceneFileBytes)
    return Status::Error(source_name + ": " + std::to_string(json_text.size()) +
                         " bytes is too large for a scene file (the limit is " +
                         std::to_string(kMaxSceneFileBytes >> 20) + " MB)");
  // nlohmann reports errors by throwing; nothing thrown leaves this function.
  try {
    StructureGuard guard;
    Json::sax_parse(json_text.begin(), json_text.end(), &guard);
    const Json root = Json::parse(json_text.begin(), json_text.end());
    Scene scene;
    SceneParser parser(source_name, base_dir);
    RAYSTACK_RETURN_IF_ERROR(parser.Parse(root, &scene));
    return scene;
  } catch (const StructureError& e) {
    return Status::Error(source_name + ": " + (e.path.empty() ? "" : e.path + ": ") + e.what);
  } catch (const Json::parse_error& e) {
    const size_t offset = e.byte > 0 ? e.byte - 1 : 0;
    const std::string detail = Detail(e.what());
    return Status::Error(source_name + ":" + LineColumn(json_text, offset) +
                         ": invalid JSON: " + detail + SlipHint(detail, json_text, offset));
  } catch (const Json::out_of_range& e) {
    // A number beyond double range ("number overflow parsing '1e400'"): find it for the place.
    std::string detail = Detail(e.what());
    const size_t open = detail.find('\''), close = detail.rfind('\'');
    std::string place;
    if (open != std::string::npos && close > open + 1) {
      const size_t at = json_text.find(detail.substr(open + 1, close - open - 1));
      if (at != std::string_view::npos) place = ":" + LineColumn(json_text, at);
    }
    return Status::Error(source_name + place + ": invalid JSON: " + detail);
  } catch (const std::bad_alloc&) {
    return Status::Error(source_name + ": out of memory while parsing");
  } catch (const std::exception& e) {
    return Status::Error(source_name + ": invalid JSON: " + Detail(e.what()));
  }
}

Expected<Scene> LoadScene(const std::string& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) return Status::Error(path + ": is a directory, not a scene file");
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::Error(path + ": cannot open: " + std::strerror(errno));
  // Read at most one byte past the limit: enough to tell a file is too large, whatever it is
  // (a pipe or /dev/zero has no size to ask for, so the size is only a hint).
  const uintmax_t size = fs::file_size(path, ec);
  if (!ec && size > kMaxSceneFileBytes)
    return Status::Error(path + ": " + std::to_string(size) +
                         " bytes is too large for a scene file (the limit is " +
                         std::to_string(kMaxSceneFileBytes >> 20) + " MB)");
  std::string text(ec ? kMaxSceneFileBytes + 1 : static_cast<size_t>(size) + 1, '\0');
  in.read(text.data(), static_cast<std::streamsize>(text.size()));
  if (in.bad()) return Status::Error(path + ": read error: " + std::strerror(errno));
  text.resize(static_cast<size_t>(in.gcount()));
  // Relative paths are the scene file's neighbours; a scene read from a pipe or a descriptor
  // (/dev/stdin, even redirected from a file; a process substitution's /dev/fd/N) has none,
  // so they are the working folder's (not /dev's).
  const std::string folder = fs::path(path).lexically_normal().parent_path().string();
  const bool stream = !fs::is_regular_file(path, ec) || folder == "/dev" ||
                      folder == "/dev/fd" || folder.rfind("/proc/", 0) == 0;
  return ParseScene(text, path, stream ? "" : fs::path(path).parent_path().string());
}

}  // namespace raystack::render
