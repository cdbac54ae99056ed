#pragma once
// (placeholder until the scene library lands)
#include <span>
#include <vector>
#include "common/render/scene.h"
#include "common/store/format.h"
namespace raystack::render {
class MaterialTable {
 public:
  static MaterialTable Build(std::span<const store::MaterialRecord> records, const Scene& scene) {
    MaterialTable t; t.default_ = scene.default_material;
    for (const auto& r : records) { Material m; m.albedo = {r.kd[0], r.kd[1], r.kd[2]}; t.m_.push_back(m); }
    return t;
  }
  const Material& Get(uint32_t id) const { return id < m_.size() ? m_[id] : default_; }
  bool any_specular() const { bool s = default_.specular(); for (auto& m : m_) s |= m.specular(); return s; }
  bool any_emissive() const { bool s = default_.emissive(); for (auto& m : m_) s |= m.emissive(); return s; }
  size_t size() const { return m_.size(); }
 private:
  std::vector<Material> m_; Material default_;
};
}  // namespace raystack::render
