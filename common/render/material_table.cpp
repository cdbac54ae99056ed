#include "common/render/material_table.h"

#include <cmath>
#include <cstring>
#include <map>
#include <string>

#include "common/base/log.h"

namespace raystack::render {
namespace {

constexpr const char* kComponent = "render";

// Stores are written from arbitrary MTL files; a NaN or a negative there must not reach
// shading.
Vec3f Clean(const float v[3]) {
  Vec3f out;
  for (int k = 0; k < 3; ++k) out[k] = std::isfinite(v[k]) && v[k] > 0 ? v[k] : 0.0f;
  return out;
}

bool NonZero(Vec3f v) { return v.x > 0 || v.y > 0 || v.z > 0; }

std::string RecordName(const store::MaterialRecord& record) {
  return std::string(record.name, strnlen(record.name, sizeof record.name));
}

// The store keeps names to 63 bytes (the converter warns when it cuts one): materials whose
// names differ only after that, or a name in two of the store's models, are one key here, and
// an override of "one" of them silently changes all of them.
void WarnAboutSharedOverrides(const std::map<std::string, size_t>& matched,
                              const std::string& source) {
  for (const auto& [name, count] : matched)
    if (count > 1)
      LOG_WARNING(kComponent,
                  "%s: materials.%s matches %zu materials of the store (their names are equal "
                  "in the store, which keeps %zu bytes of a name); the override changes all of "
                  "them. To tell them apart, rename them in the MTL file and convert again",
                  source.c_str(), name.c_str(), count, sizeof(store::MaterialRecord::name) - 1);
}

}  // namespace

Material MaterialFromMtl(const store::MaterialRecord& record) {
  Material m;
  m.emission = Clean(record.ke);
  const int illum = record.illum;
  if (illum == 3 || illum == 5) {
    m.type = MaterialType::kMirror;
    m.albedo = Clean(record.ks);
  } else if (illum == 4 || illum == 6 || illum == 7 || illum == 9 || record.d < 1) {
    m.type = MaterialType::kGlass;
    // Ni < 1 (or missing, NaN) cannot be glass in air; 1.5 is common glass.
    m.ior = record.ni >= 1 ? std::min(record.ni, kMaxIor) : 1.5f;
    const Vec3f ks = Clean(record.ks);
    m.albedo = NonZero(ks) ? ks : Vec3f{1, 1, 1};
  } else {
    m.type = MaterialType::kDiffuse;
    m.albedo = Clean(record.kd);
  }
  return m;
}

MaterialTable MaterialTable::Build(std::span<const store::MaterialRecord> records,
                                   const Scene& scene) {
  MaterialTable table;
  table.default_ = scene.default_material;
  table.materials_.reserve(records.size());
  std::map<std::string, size_t> matched;  // override key -> store materials it replaces
  for (const store::MaterialRecord& record : records) {
    const std::string name = RecordName(record);
    auto it = scene.overrides.find(name);
    // The store keeps names to 63 bytes: a longer override key matches its truncation.
    if (it == scene.overrides.end() && name.size() == sizeof record.name - 1) {
      for (auto o = scene.overrides.begin(); o != scene.overrides.end(); ++o)
        if (o->first.size() > name.size() && o->first.compare(0, name.size(), name) == 0) it = o;
    }
    if (it != scene.overrides.end()) {
      ++matched[it->first];
      table.materials_.push_back(it->second);
    } else {
      table.materials_.push_back(MaterialFromMtl(record));
    }
  }
  WarnAboutSharedOverrides(matched, scene.source);
  constexpr size_t kNamedUnused = 8;  // then a count: a scene may list thousands
  size_t unused = 0;
  for (const auto& [name, material] : scene.overrides) {
    if (matched.count(name) || ++unused > kNamedUnused) continue;
    LOG_WARNING(kComponent,
                "%s: materials.%s: the store has no material of that name; the override is "
                "unused",
                scene.source.c_str(), name.c_str());
  }
  if (unused > kNamedUnused)
    LOG_WARNING(kComponent, "%s: %zu more material overrides name no material of the store",
                scene.source.c_str(), unused - kNamedUnused);
  table.any_specular_ = table.default_.specular();
  table.any_emissive_ = table.default_.emissive();
  for (const Material& m : table.materials_) {
    table.any_specular_ = table.any_specular_ || m.specular();
    table.any_emissive_ = table.any_emissive_ || m.emissive();
  }
  return table;
}

}  // namespace raystack::render
