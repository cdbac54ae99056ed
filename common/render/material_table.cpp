#include "common/render/material_table.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstring>
#include <map>
#include <string>
#include <utility>
#include <vector>

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

const char* TypeName(MaterialType type) {
  return type == MaterialType::kMirror ? "a mirror" : type == MaterialType::kGlass ? "glass" : "diffuse";
}

float MaxComponent(Vec3f v) { return std::max(v.x, std::max(v.y, v.z)); }

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

// Edits (insertions, deletions, substitutions, ignoring case) from a to b, or `cap` + 1 once
// past `cap`.
size_t EditDistance(const std::string& a, const std::string& b, size_t cap) {
  if ((a.size() > b.size() ? a.size() - b.size() : b.size() - a.size()) > cap) return cap + 1;
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diagonal = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      const bool same = std::tolower(static_cast<unsigned char>(a[i - 1])) ==
                        std::tolower(static_cast<unsigned char>(b[j - 1]));
      const size_t next = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (same ? 0 : 1)});
      diagonal = row[j];
      row[j] = next;
    }
  }
  return std::min(row.back(), cap + 1);
}

// The store's material names, " (it has a, b, c)", or where to find them when they are many.
std::string Names(std::span<const store::MaterialRecord> records) {
  constexpr size_t kListed = 12;
  if (records.size() > kListed) return " (raystack-info STORE lists them)";
  std::string names;
  for (const store::MaterialRecord& r : records) names += (names.empty() ? "" : ", ") + RecordName(r);
  return " (it has " + names + ")";
}

// What to say of an override key no store material has: the name it was probably meant to be
// (the same but for case, or two edits away), else the store's names when they are few.
std::string NameHint(const std::string& key, std::span<const store::MaterialRecord> records) {
  constexpr size_t kCloseEdits = 2;
  std::string closest;
  size_t best = kCloseEdits + 1;
  for (const store::MaterialRecord& r : records) {
    const std::string name = RecordName(r);
    const size_t d = EditDistance(key, name, kCloseEdits);
    if (d < best) best = d, closest = name;
  }
  if (!closest.empty()) return " (did you mean \"" + closest + "\"?)";
  if (records.empty()) return " (it has none: every triangle takes materials.default)";
  return Names(records);
}

}  // namespace

Material MaterialFromMtl(const store::MaterialRecord& record, std::string* note) {
  Material m;
  m.emission = Clean(record.ke);
  const Vec3f kd = Clean(record.kd), ks = Clean(record.ks);
  const int illum = record.illum;
  const bool mirror_illum = illum == 3 || illum == 5;
  const bool glass_illum = illum == 4 || illum == 6 || illum == 7 || illum == 9;
  std::string why;
  if (mirror_illum && NonZero(ks)) {
    m.type = MaterialType::kMirror;
    m.albedo = ks;
    if (MaxComponent(kd) > MaxComponent(ks))
      why = StrFormat("its Kd (%g %g %g) is stronger than its Ks but unused (illum %d makes a "
                      "mirror of Ks)", double{kd.x}, double{kd.y}, double{kd.z}, illum);
  } else if (record.d < 1 || (glass_illum && record.ni != 1.0f)) {
    m.type = MaterialType::kGlass;
    // Ni < 1 (or NaN) cannot be glass in air; 1.5 is common glass. A transparent material
    // without Ni (d < 1: a window of one face, as SketchUp writes them) stays a clear sheet of
    // index 1, as before Ni's absence was told apart: one face refracting at 1.5 would bend all
    // that is seen through it.
    const bool clear_sheet = record.d < 1 && record.ni == 0;
    m.ior = record.ni >= 1 ? std::min(record.ni, kMaxIor) : clear_sheet ? 1.0f : 1.5f;
    m.albedo = NonZero(ks) ? ks : Vec3f{1, 1, 1};
  } else {
    m.type = MaterialType::kDiffuse;
    m.albedo = kd;
    if (mirror_illum)
      why = StrFormat("illum %d asks for a mirror, but its Ks is 0", illum);
    else if (glass_illum)
      why = StrFormat("illum %d asks for glass, but it is opaque (d 1) with Ni 1: it would be "
                      "invisible", illum);
  }
  if (note) *note = std::move(why);
  return m;
}

MaterialTable MaterialTable::Build(std::span<const store::MaterialRecord> records,
                                   const Scene& scene, bool say) {
  MaterialTable table;
  table.default_ = scene.default_material;
  table.materials_.reserve(records.size());
  std::map<std::string, size_t> matched;  // override key -> store materials it replaces
  constexpr size_t kNamedNotes = 8;  // then a count: a model may have thousands
  size_t noted = 0;
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
      std::string note;
      table.materials_.push_back(MaterialFromMtl(record, &note));
      if (say && !note.empty() && ++noted <= kNamedNotes)
        LOG_INFO(kComponent, "material '%s' renders as %s: %s", name.c_str(),
                 TypeName(table.materials_.back().type), note.c_str());
    }
  }
  if (noted > kNamedNotes)
    LOG_INFO(kComponent, "%zu more materials have a note on how they render (raystack-info "
             "lists each)", noted - kNamedNotes);
  if (say) WarnAboutSharedOverrides(matched, scene.source);
  constexpr size_t kNamedUnused = 8;  // then a count: a scene may list thousands
  size_t unused = 0;
  for (const auto& [name, material] : scene.overrides) {
    if (!say || matched.count(name) || ++unused > kNamedUnused) continue;
    LOG_WARNING(kComponent,
                "%s: materials.%s: the store has no material of that name; the override is "
                "unused%s",
                scene.source.c_str(), name.c_str(), NameHint(name, records).c_str());
  }
  // A "default" beside a store whose faces carry MTL materials changed nothing, without a word
  // (a scene author gave the Cornell box a default mirror: the same image, bit for bit).
  if (say && scene.default_given && !records.empty())
    LOG_WARNING(kComponent,
                "%s: materials.default applies only to triangles without a material, and the "
                "store's come with %zu from the model's MTL: it changes nothing where every face "
                "has one; to change those, name them in \"materials\"%s",
                scene.source.c_str(), records.size(), Names(records).c_str());
  if (say && unused > kNamedUnused)
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
