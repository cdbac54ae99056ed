#pragma once
// The materials a render shades with, indexed by the store's material ids: the store's MTL
// records mapped to the renderer's three material types, with the scene's overrides applied.
// Built once per scene; immutable afterwards, so every thread may read it.

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "common/render/scene.h"
#include "common/store/format.h"

namespace raystack::render {

// Material for an MTL record: Ke > 0 -> emission = Ke; illum 3 or 5 with Ks > 0 -> mirror with
// albedo Ks; d < 1, or illum 4, 6, 7 or 9 with an Ni other than 1 -> glass with ior Ni (1.5 if
// Ni < 1 or not given, 1 if not given with d < 1: a clear sheet) and albedo = Ks if nonzero else
// [1,1,1]; otherwise diffuse with albedo
// Kd. The first rule that matches wins, in this order. Exporters write these illums for
// materials that are neither (CityEngine: illum 3 with Ks 0 for its Lambert materials, a black
// mirror; Maya: illum 4 with Ni 1 and d 1 for every Lambert, an invisible glass), hence the
// Ks and Ni conditions. So that shading never sees what a scene file could not say:
// non-finite or negative MTL colours become 0 and Ni above 4 becomes 4 (the range LoadScene
// accepts). `note`, when given, receives why the record's illum was not followed or what it
// leaves unused (empty when nothing is), for messages.
Material MaterialFromMtl(const store::MaterialRecord& record, std::string* note = nullptr);

class MaterialTable {
 public:
  MaterialTable() = default;  // only the default material

  // One entry per store material (overridden by the scene's materials keyed by MTL name), plus
  // the scene's default for triangles without a material (store::kNoMaterial). An override
  // naming a material the store does not have is logged as a warning (a scene may be shared
  // by stores with different materials).
  // `say` false builds silently: the slaves of a job but one, so that a job says it once.
  static MaterialTable Build(std::span<const store::MaterialRecord> records, const Scene& scene,
                             bool say = true);

  // kNoMaterial or out of range -> the default.
  const Material& Get(uint32_t material_id) const {
    return material_id < materials_.size() ? materials_[material_id] : default_;
  }
  // Whether any entry (the default included) is a mirror or glass / emits: lets an engine skip
  // whole code paths (secondary specular rays, emitter sampling) for scenes without them.
  bool any_specular() const { return any_specular_; }
  bool any_emissive() const { return any_emissive_; }
  // Entries including the default: store materials + 1 (ids 0 .. size() - 2 are the store's;
  // any other id reads the default).
  size_t size() const { return materials_.size() + 1; }
  const Material& default_material() const { return default_; }

 private:
  std::vector<Material> materials_;  // by store material id
  Material default_;
  bool any_specular_ = false;
  bool any_emissive_ = false;
};

}  // namespace raystack::render
