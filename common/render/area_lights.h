#pragma once
// The emissive triangles a path tracer aims at (next-event estimation): the store's lights.bin
// with the scene's overrides applied (an emitter the scene makes dark is left out, one it
// recolours shines its new colour). A triangle is chosen in proportion to its power (area
// times mean emitted radiance), then a point uniformly on it, so bright large lights get the
// rays. Immutable once built: every ray thread reads it.
//
// A triangle made emissive by the scene file alone is not here (lights.bin lists what the MTL
// made emissive): such emitters are found only by the rays that meet them, as before.

#include <cstdint>
#include <span>
#include <vector>

#include "common/geometry/vec.h"
#include "common/render/material_table.h"
#include "common/store/format.h"

namespace raystack::render {

class AreaLights {
 public:
  AreaLights() = default;
  AreaLights(std::span<const store::EmitterRecord> emitters, const MaterialTable& materials);

  bool empty() const { return triangles_.empty(); }
  size_t size() const { return triangles_.size(); }
  // The power the triangles emit, both sides (2 pi x area x radiance, the radiance measured as
  // the mean of its channels), for choosing between them and point lights.
  double power() const { return power_; }
  // The density per unit area with which Pick returns a point on a triangle of store material
  // `material` (the same on each of them: a triangle's probability is its power, area times
  // radiance, over the total), or 0 when the material's triangles are not sampled here. For
  // weighing an emitter a diffuse ray meets against the points Pick gives (multiple
  // importance sampling).
  float PdfArea(uint32_t material) const {
    return material < pdf_area_.size() ? pdf_area_[material] : 0.0f;
  }

  struct Sample {
    Vec3f point;     // on the triangle
    Vec3f error;     // per axis, a bound on the rounding of `point`
    Vec3f normal;    // the triangle's unit normal (emission leaves both sides)
    Vec3f emission;  // its radiance
    float pdf_area;  // the density of `point` per unit area: P(triangle) / area
  };
  // u_choice (48 random bits: with 24, a triangle's chance among a million was off by 5%), u1,
  // u2 uniform in [0, 1). Not on an empty set.
  Sample Pick(double u_choice, float u1, float u2) const;

 private:
  struct Triangle {
    Vec3f p0, e1, e2;  // corner 0 and the edges to corners 1 and 2
    Vec3f error;       // (|p0| + |p1| + |p2|) scaled to a bound on a point's rounding
    Vec3f normal;
    Vec3f emission;
    uint32_t material;  // its store material (pdf_area_)
  };
  std::vector<Triangle> triangles_;
  std::vector<double> cumulative_;  // probability of choosing a triangle at or before i
  std::vector<float> pdf_area_;    // by store material (0: not sampled)
  double power_ = 0;
};

}  // namespace raystack::render
