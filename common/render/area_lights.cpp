#include "common/render/area_lights.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace raystack::render {

AreaLights::AreaLights(std::span<const store::EmitterRecord> emitters,
                       const MaterialTable& materials) {
  const size_t material_count = materials.size() - 1;  // the store's, without the default
  pdf_area_.assign(material_count, 0.0f);
  std::vector<double> power;
  std::vector<double> radiance_of(material_count, 0.0);  // materials with a triangle here
  for (const store::EmitterRecord& e : emitters) {
    if (e.material >= material_count) continue;
    const Material& m = materials.Get(e.material);
    const Vec3f p0{e.p[0][0], e.p[0][1], e.p[0][2]}, p1{e.p[1][0], e.p[1][1], e.p[1][2]},
        p2{e.p[2][0], e.p[2][1], e.p[2][2]};
    const Vec3f cross = Cross(p1 - p0, p2 - p0);
    // In double: at the largest scales a model may have (1e18) the float square overflows.
    const double cx = cross.x, cy = cross.y, cz = cross.z;
    const double area = 0.5 * std::sqrt(cx * cx + cy * cy + cz * cz);
    const double ex = m.emission.x, ey = m.emission.y, ez = m.emission.z;
    const double radiance = (ex + ey + ez) / 3;
    // The scene made it dark (then no triangle of its material is here, and its hits add
    // nothing either), or it has no area a ray could meet.
    if (!m.emissive() || !(area > 0) || !std::isfinite(area) || !(radiance > 0)) continue;
    Triangle t;
    t.p0 = p0;
    t.e1 = p1 - p0;
    t.e2 = p2 - p0;
    for (int a = 0; a < 3; ++a)  // a few ulps of the corners: what interpolating them rounds
      t.error[a] = (std::fabs(p0[a]) + std::fabs(p1[a]) + std::fabs(p2[a])) * 0x1p-20f;
    t.normal = Normalize(cross * static_cast<float>(1 / (2 * area)));  // unit before the square
    t.emission = m.emission;
    t.material = e.material;
    triangles_.push_back(t);
    power.push_back(area * radiance);
    radiance_of[e.material] = radiance;
  }
  double total = 0;
  for (const double w : power) total += w;
  power_ = 2 * std::numbers::pi * total;
  double running = 0;
  cumulative_.reserve(triangles_.size());
  for (const double w : power) cumulative_.push_back(running += w / total);
  if (!cumulative_.empty()) cumulative_.back() = 1.0;
  // A triangle's chance over its area, power / total / area, is its material's radiance / total:
  // one density for all the triangles of a material.
  for (size_t m = 0; m < material_count && total > 0; ++m)
    pdf_area_[m] = static_cast<float>(radiance_of[m] / total);
}

AreaLights::Sample AreaLights::Pick(double u_choice, float u1, float u2) const {
  const size_t i = std::min<size_t>(
      triangles_.size() - 1,
      static_cast<size_t>(std::upper_bound(cumulative_.begin(), cumulative_.end(), u_choice) -
                          cumulative_.begin()));
  const Triangle& t = triangles_[i];
  // Uniform on the triangle: barycentrics (1 - sqrt(u1), sqrt(u1) (1 - u2), sqrt(u1) u2).
  const float su = std::sqrt(u1);
  Sample s;
  s.point = t.p0 + t.e1 * (su * (1 - u2)) + t.e2 * (su * u2);
  s.error = t.error;
  s.normal = t.normal;
  s.emission = t.emission;
  s.pdf_area = pdf_area_[t.material];
  return s;
}

}  // namespace raystack::render
