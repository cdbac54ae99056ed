#pragma once
// What happens when a radiance ray's traversal ends: emission and background are added to its
// sample, and the integrator spawns the rays the hit needs (shadow rays towards lights,
// specular or diffuse continuations). Only what the scene needs: no lights, no shadow rays;
// no specular material, no specular rays.
//
// Pure: the output depends only on the record, the pixel, the sample and the scene (random
// numbers are hashes of (seed, pixel, sample, bounce)), so rays may finish in any order.

#include <cstdint>
#include <vector>

#include "common/render/area_lights.h"
#include "common/render/material_table.h"
#include "common/render/random.h"
#include "common/render/scene.h"
#include "slave/ray_record.h"

namespace raystack::slave {

struct ShadeOutput {
  Vec3f radiance{0, 0, 0};          // to add to the sample
  std::vector<RayRecord> children;  // rays to trace next (reused between calls)
  // Primary rays only: the Z, normal and albedo layers.
  bool primary = false;
  bool hit = false;
  float z = 0;
  Vec3f normal{0, 0, 0}, albedo{0, 0, 0};
};

class Shader {
 public:
  // `area`: the emissive triangles path tracing aims at (null or empty: none); it must
  // outlive the shader.
  Shader(const render::Scene& scene, const render::MaterialTable& materials,
         const render::AreaLights* area = nullptr);

  void Finish(const RayRecord& ray, uint32_t pixel, uint32_t sample, ShadeOutput* out) const;

  bool path() const { return path_; }
  // Whether every shadow ray ends at a point light (no emitters to aim at): then those of
  // neighbouring primary hits run side by side, and walk a tree well as one packet.
  bool ShadowsEndAtPoints() const { return area_ == nullptr || area_->empty(); }

 private:
  // `p`: the hit point, where the light's distance and angles are measured; `origin`: p moved
  // off the surface (OffsetRayOrigin), where shadow rays start. Measured from `origin`, the
  // light was off by the move, ~8 ulps of |p|: 0.1 at 1e5 from the axes, where a plane 1 below
  // its light came out 2% darker on average and up to 24% off (found by a rendering researcher).
  void DirectLight(const RayRecord& ray, Vec3f p, Vec3f origin, Vec3f n, Vec3f albedo,
                   uint32_t pixel, uint32_t sample, ShadeOutput* out) const;
  // One shadow ray towards a point on an emissive triangle (path tracing), its weight the
  // estimate's times `scale` (1 / the probability of choosing the emitters).
  void EmitterLight(const RayRecord& ray, Vec3f p, Vec3f origin, Vec3f n, Vec3f albedo,
                    float scale, const render::SampleRandom& rng, ShadeOutput* out) const;
  // The share of an emitter's radiance a ray that met it adds: all of it, except for a diffuse
  // ray meeting an emitter that EmitterLight samples too (the balance heuristic's weight).
  float EmissionWeight(const RayRecord& ray, Vec3f ng) const;
  void Spawn(const RayRecord& parent, RayType type, Vec3f origin, Vec3f direction, Vec3f weight,
             ShadeOutput* out) const;

  const render::Scene& scene_;
  const render::MaterialTable& materials_;
  const render::AreaLights* const area_;  // null unless path tracing has emitters to aim at
  const bool path_;
  const int max_depth_;
  const uint64_t seed_;
  const bool background_;
  // Path tracing's choice of a light (LightChance): by power (a point light's 4 pi x intensity,
  // the emitters' AreaLights::power(), intensities and radiances measured as the mean of their
  // channels) nine times in ten, uniformly in one. The running sums of the point lights'
  // powers, and the emitters' power.
  std::vector<double> point_power_sums_;
  double emitters_power_ = 0;
  // 1 / the chance of choosing the emitters, where they may be chosen (EmissionWeight).
  float emitters_scale_ = 1;
  // The chance of choice `power` of `total` among `choices`.
  static double LightChance(double power, double total, size_t choices);
};

}  // namespace raystack::slave
