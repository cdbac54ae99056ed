#include "slave/shading.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "common/geometry/offset_ray.h"
#include "common/geometry/ray.h"
#include "common/render/random.h"
#include "common/store/format.h"

namespace raystack::slave {
namespace {

using render::Material;
using render::MaterialType;
using render::RandomUse;
using render::SampleRandom;

bool NonZero(Vec3f v) { return v.x > 0 || v.y > 0 || v.z > 0; }
float MaxComponent(Vec3f v) { return std::max(v.x, std::max(v.y, v.z)); }

// Whitted's glass traces both lobes, so glass seen through glass doubles the rays at every
// bounce: 2^max_depth of them (depth 64 in a glass box did not end). A lobe weighing less than
// this is not traced (adaptive tree depth, Hall and Greenberg 1983): it adds to the pixel
// under 1/1024 of the radiance it would see. Path tracing, which picks one lobe, is not
// affected.
constexpr float kMinWhittedLobeWeight = 1.0f / 1024;
bool Traced(Vec3f lobe_weight) { return MaxComponent(lobe_weight) >= kMinWhittedLobeWeight; }

// Fresnel reflectance of a smooth dielectric; cos_i > 0 on the incident side, eta = n_i / n_t.
float FresnelDielectric(float cos_i, float eta, float* cos_t) {
  const float sin2_t = eta * eta * std::max(0.0f, 1.0f - cos_i * cos_i);
  if (sin2_t >= 1.0f) {
    *cos_t = 0;
    return 1.0f;  // total internal reflection
  }
  *cos_t = std::sqrt(1.0f - sin2_t);
  const float rs = (eta * cos_i - *cos_t) / (eta * cos_i + *cos_t);
  const float rp = (cos_i - eta * *cos_t) / (cos_i + eta * *cos_t);
  return 0.5f * (rs * rs + rp * rp);
}

Vec3f Reflect(Vec3f d, Vec3f n) { return d - n * (2.0f * Dot(d, n)); }

// Any unit vector perpendicular to n, stably (Duff et al. 2017).
void Basis(Vec3f n, Vec3f* t, Vec3f* b) {
  const float sign = std::copysign(1.0f, n.z);
  const float a = -1.0f / (sign + n.z);
  const float c = n.x * n.y * a;
  *t = {1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x};
  *b = {c, sign + n.y * n.y * a, -n.y};
}

}  // namespace

Shader::Shader(const render::Scene& scene, const render::MaterialTable& materials,
               const render::AreaLights* area)
    : scene_(scene),
      materials_(materials),
      area_(scene.integrator.type == render::IntegratorType::kPath && area && !area->empty()
                ? area
                : nullptr),
      path_(scene.integrator.type == render::IntegratorType::kPath),
      max_depth_(scene.integrator.max_depth),
      seed_(scene.integrator.seed),
      background_(NonZero(scene.background)) {
  double sum = 0;
  for (const render::PointLight& light : scene.lights) {
    const Vec3f i = light.intensity;
    sum += 4 * std::numbers::pi * ((double{i.x} + double{i.y} + double{i.z}) / 3);
    point_power_sums_.push_back(sum);
  }
  if (area_) {
    emitters_power_ = area_->power();
    emitters_scale_ = static_cast<float>(
        1 / LightChance(emitters_power_, sum + emitters_power_, scene.lights.size() + 1));
  }
}

// By power alone, a dim light beside a bright one was next to never chosen, so with few samples
// it was missing from the image (a lamp beside a sun 1e8 times as strong: its 4% of the image
// gone); one choice in ten uniform keeps each light's chance at least 1/10 of 1/choices.
constexpr double kUniformShare = 0.1;

double Shader::LightChance(double power, double total, size_t choices) {
  return (1 - kUniformShare) * (total > 0 ? power / total : 0.0) +
         kUniformShare / static_cast<double>(choices);
}

void Shader::Spawn(const RayRecord& parent, RayType type, Vec3f origin, Vec3f direction,
                   Vec3f weight, ShadeOutput* out) const {
  RayRecord r{};
  r.origin = origin;
  r.direction = direction;
  r.tmax = type == RayType::kShadow ? 1.0f : std::numeric_limits<float>::infinity();
  r.hit_id = kInvalidId;
  r.slot = parent.slot;
  r.weight = weight;
  r.material = store::kNoMaterial16;
  r.type = static_cast<uint8_t>(type);
  r.depth = static_cast<uint8_t>(type == RayType::kShadow ? parent.depth : parent.depth + 1);
  r.priority = parent.priority;
  out->children.push_back(r);
}

void Shader::DirectLight(const RayRecord& ray, Vec3f p, Vec3f origin, Vec3f n, Vec3f albedo,
                         uint32_t pixel, uint32_t sample, ShadeOutput* out) const {
  const auto& lights = scene_.lights;
  // Path tracing chooses one of the point lights or the emitters (as one more choice). The
  // emitters only where the path may bounce on: light from an emitter reaches this point as a
  // path one segment longer, which the depth limit cuts when the bounce is not traced (so the
  // image converges to the one the bounces alone would give).
  const bool emitters = area_ && ray.depth < max_depth_;
  if ((lights.empty() && !emitters) || !NonZero(albedo)) return;
  size_t first = 0, last = lights.size();
  float scale = 1.0f;
  if (path_) {
    // Next-event estimation: one light, chosen mostly by power (chosen uniformly, ten negligible
    // fill lights took ten elevenths of the shadow rays from the one that lit the scene: +31% of
    // variance at 64 samples), its estimate divided by its chance (LightChance).
    const double points = point_power_sums_.empty() ? 0.0 : point_power_sums_.back();
    const double total = points + (emitters ? emitters_power_ : 0.0);
    if (!(total > 0)) return;  // every light dark: nothing to light with
    const size_t choices = lights.size() + (emitters ? 1 : 0);
    const SampleRandom rng(seed_, pixel, sample);
    // 48 random bits: with 24, a light with less than 2^-24 of the power was never chosen.
    const double u = double{rng.Uniform(ray.depth, RandomUse::kLightChoice)} +
                     double{rng.Uniform(ray.depth, RandomUse::kLightChoiceLow)} * 0x1p-24;
    size_t chosen;  // a point light's index, or lights.size() for the emitters
    if (u < kUniformShare) {
      chosen = std::min(choices - 1, static_cast<size_t>(u / kUniformShare * static_cast<double>(choices)));
    } else {
      // By power: the first light whose running sum passes u's place in `total` (a dark light
      // adds nothing to the sum, so it is never the first to pass it); past them, the emitters.
      const double at = (u - kUniformShare) / (1 - kUniformShare) * total;
      chosen = at < points ? static_cast<size_t>(std::upper_bound(point_power_sums_.begin(),
                                                                  point_power_sums_.end(), at) -
                                                 point_power_sums_.begin())
                           : lights.size();
      if (chosen == lights.size() && !emitters) chosen = lights.size() - 1;  // (rounding)
    }
    if (chosen == lights.size()) {
      EmitterLight(ray, p, origin, n, albedo, emitters_scale_, rng, out);
      return;
    }
    const double power = point_power_sums_[chosen] - (chosen > 0 ? point_power_sums_[chosen - 1] : 0.0);
    scale = static_cast<float>(1 / LightChance(power, total, choices));
    first = chosen;
    last = first + 1;
  }
  for (size_t i = first; i < last; ++i) {
    const Vec3f to_light = lights[i].position - p;
    const float d2 = Dot(to_light, to_light);
    if (!(d2 > 0)) continue;
    const float cos_theta = Dot(n, to_light) / std::sqrt(d2);
    if (!(cos_theta > 0)) continue;
    // Lambertian BRDF albedo/pi times the irradiance I cos / d^2 of a point light.
    const Vec3f weight = ray.weight * albedo * lights[i].intensity *
                         (scale * cos_theta / (d2 * std::numbers::pi_v<float>));
    if (!NonZero(weight)) continue;
    Spawn(ray, RayType::kShadow, origin, lights[i].position - origin, weight, out);
  }
}

void Shader::EmitterLight(const RayRecord& ray, Vec3f p, Vec3f origin, Vec3f n, Vec3f albedo,
                          float scale, const SampleRandom& rng, ShadeOutput* out) const {
  const double u_choice = double{rng.Uniform(ray.depth, RandomUse::kEmitterChoice)} +
                          double{rng.Uniform(ray.depth, RandomUse::kEmitterChoiceLow)} * 0x1p-24;
  const render::AreaLights::Sample s =
      area_->Pick(u_choice, rng.Uniform(ray.depth, RandomUse::kEmitterU),
                  rng.Uniform(ray.depth, RandomUse::kEmitterV));
  // The shadow ray ends just off the emitter on the side facing the shading point, so that the
  // emitter itself (and its coplanar neighbours) lie beyond the segment it tests. Off by more
  // than the point's own rounding: the ray's direction (target - origin) is rounded to the
  // origin's magnitude, and from 50 times farther than the emitter lies from the axes' plane,
  // its end landed past the emitter, which then shadowed itself (half the rays; found by the
  // day's review). A blocker closer to the emitter than ~2^-22 of the scene is not seen.
  const Vec3f facing = Dot(s.normal, origin - s.point) >= 0 ? s.normal : -s.normal;
  Vec3f margin;
  for (int a = 0; a < 3; ++a)
    margin[a] = std::max(s.error[a], (std::fabs(origin[a]) + std::fabs(s.point[a])) * 0x1p-22f);
  // At most half the way back to the shading point: 3 * 2^-20 of the corners is 0.29 at 1e5,
  // and a lamp 0.25 over a floor there had every shadow ray's end below the floor, the floor
  // black outside the lamp's footprint (found by the day's review).
  const float gap = Dot(facing, origin - s.point);
  if (!(gap > 0)) return;  // in the emitter's plane (or NaN): it lights nothing there
  const float step = std::fabs(facing.x) * margin.x + std::fabs(facing.y) * margin.y +
                     std::fabs(facing.z) * margin.z;
  if (step > 0.5f * gap) margin = margin * (0.5f * gap / step);
  const Vec3f target = OffsetRayOrigin(s.point, facing, margin);
  const Vec3f to_light = s.point - p;  // the geometry's; the shadow ray runs origin -> target
  const float d2 = Dot(to_light, to_light);
  if (!(d2 > 0)) return;
  const float d = std::sqrt(d2);
  const float cos_surface = Dot(n, to_light) / d;
  const float cos_light = -Dot(facing, to_light) / d;
  if (!(cos_surface > 0) || !(cos_light > 0)) return;
  // Lambertian BRDF albedo/pi times L cos cos' / d^2, over the density of the point per area,
  // weighed against the diffuse bounce that could have met the same point (the balance
  // heuristic; EmissionWeight gives that ray the rest): near an emitter, where 1/d^2 is large,
  // the bounce takes most of the weight, and the fireflies it would make here do not appear.
  // The weight's densities are the ones EmissionWeight sees, from where the bounce starts
  // (`origin`): from p, the two weights of one path summed to more than 1 by ~2 offsets over
  // the distance (+5% under a lamp 1 over a floor at 1e5; the day's review).
  const Vec3f to_mis = s.point - origin;
  const float d2_mis = Dot(to_mis, to_mis);
  const float d_mis = std::sqrt(d2_mis);
  const float cos_light_mis = -Dot(facing, to_mis) / d_mis;
  if (!(cos_light_mis > 0)) return;  // then EmissionWeight gives the bounce the whole weight
  const float light_pdf = s.pdf_area * d2_mis / (cos_light_mis * scale);  // per solid angle
  const float bounce_pdf =
      CosineOf(QuantizeCosine(Dot(n, to_mis) / d_mis)) / std::numbers::pi_v<float>;
  const float mis = 1.0f / (1.0f + bounce_pdf / light_pdf);  // an infinite light_pdf gives 1
  const Vec3f weight = ray.weight * albedo * s.emission *
                       (mis * scale * cos_surface * cos_light /
                        (d2 * std::numbers::pi_v<float> * s.pdf_area));
  if (!NonZero(weight) || !std::isfinite(MaxComponent(weight))) return;
  Spawn(ray, RayType::kShadow, origin, target - origin, weight, out);
}

float Shader::EmissionWeight(const RayRecord& ray, Vec3f ng) const {
  if (!area_ || TypeOf(ray) != RayType::kDiffuse) return 1.0f;
  const float pdf_area = area_->PdfArea(ray.material);
  if (!(pdf_area > 0)) return 1.0f;  // not sampled by EmitterLight: only found this way
  const float cos_light = -Dot(ng, ray.direction);  // ng faces the ray's origin
  if (!(cos_light > 0)) return 1.0f;
  const float light_pdf = pdf_area * ray.tmax * ray.tmax / (cos_light * emitters_scale_);  // as EmitterLight
  const float bounce_pdf = CosineOf(ray.origin_cosine) / std::numbers::pi_v<float>;
  return 1.0f / (1.0f + light_pdf / bounce_pdf);  // 0 where the bounce had no density
}

void Shader::Finish(const RayRecord& ray, uint32_t pixel, uint32_t sample,
                    ShadeOutput* out) const {
  out->radiance = {0, 0, 0};
  out->children.clear();
  out->primary = TypeOf(ray) == RayType::kPrimary;
  out->hit = ray.hit_id != kInvalidId;
  if (!out->hit) {
    if (background_) out->radiance = ray.weight * scene_.background;
    if (out->primary) {
      out->z = std::numeric_limits<float>::infinity();
      out->normal = out->albedo = {0, 0, 0};
    }
    return;
  }
  const Material& m = materials_.Get(ray.material == store::kNoMaterial16 ? store::kNoMaterial
                                                                          : ray.material);
  const Vec3f n = DecodeNormal(ray.normal);  // faces the side the ray came from
  // New rays start off the surface along its own normal (on n's side, or the other for
  // refraction): the hit point's error bound is against the plane, and projected on a shading
  // normal leaning far from it the bound may not leave the plane (1 origin in ~4,000 on the
  // wrong side at 70 degrees). The same as n for a model without vertex normals.
  const Vec3f ng = DecodeNormal(ray.geometric_normal);
  const Vec3f p = ray.origin + ray.direction * ray.tmax;
  // Rebuilt from the ray, p carries the rounding of the ray's origin: a far camera's hit
  // points need a larger offset than their own magnitude suggests (offset_ray.h).
  const Vec3f p_error = HitPointError(ray.origin, ray.direction, ray.tmax);
  if (out->primary) {
    out->z = ray.tmax;
    out->normal = n;
    out->albedo = m.albedo;
  }
  if (m.emissive()) out->radiance = ray.weight * m.emission * EmissionWeight(ray, ng);
  const bool can_bounce = ray.depth < max_depth_;
  const SampleRandom rng(seed_, pixel, sample);
  switch (m.type) {
    case MaterialType::kDiffuse: {
      const Vec3f above = OffsetRayOrigin(p, ng, p_error);  // shadow rays and the bounce
      DirectLight(ray, p, above, n, m.albedo, pixel, sample, out);
      if (!path_ || !can_bounce || !NonZero(m.albedo)) break;
      Vec3f weight = ray.weight * m.albedo;  // cosine sampling: cos/pdf cancels the 1/pi
      if (ray.depth >= 3) {                  // Russian roulette keeps the estimate unbiased
        const float q = std::min(0.95f, MaxComponent(weight));
        if (!(rng.Uniform(ray.depth, RandomUse::kRoulette) < q)) break;
        weight = weight * (1.0f / q);
      }
      const float u1 = rng.Uniform(ray.depth, RandomUse::kBsdfU);
      const float u2 = rng.Uniform(ray.depth, RandomUse::kBsdfV);
      const float r = std::sqrt(u1), phi = 2.0f * std::numbers::pi_v<float> * u2;
      Vec3f t, b;
      Basis(n, &t, &b);
      const Vec3f dir = Normalize(t * (r * std::cos(phi)) + b * (r * std::sin(phi)) +
                                  n * std::sqrt(std::max(0.0f, 1.0f - u1)));
      Spawn(ray, RayType::kDiffuse, above, dir, weight, out);
      out->children.back().origin_cosine = QuantizeCosine(Dot(n, dir));
      break;
    }
    case MaterialType::kMirror: {
      if (!can_bounce || !NonZero(m.albedo)) break;
      Vec3f reflected = Normalize(Reflect(ray.direction, n));
      // Near an outline a shading normal can send the reflection under the surface, where it
      // would meet the surface itself and be lost: a smooth mirror sphere in a white world went
      // dark at its rim. There the surface's own normal reflects it.
      if (!(Dot(reflected, ng) > 0)) reflected = Normalize(Reflect(ray.direction, ng));
      Spawn(ray, RayType::kSpecular, OffsetRayOrigin(p, ng, p_error), reflected,
            ray.weight * m.albedo, out);
      break;
    }
    case MaterialType::kGlass: {
      if (!can_bounce || !NonZero(m.albedo)) break;
      const bool entering = !(ray.flags & kHitBackFace);
      const float eta = entering ? 1.0f / m.ior : m.ior;
      // The interface's lobes with normal `nn`: a shading normal's may leave the reflection
      // under the surface or the refraction above it (near an outline: the rim of a smooth glass
      // sphere went dark); then both come from the surface's own normal, as for a flat face.
      float cos_i, cos_t, f;
      Vec3f reflected, refracted;
      const auto lobes = [&](Vec3f nn) {
        cos_i = std::min(1.0f, std::max(0.0f, -Dot(ray.direction, nn)));
        f = FresnelDielectric(cos_i, eta, &cos_t);
        reflected = Normalize(Reflect(ray.direction, nn));
        refracted = Normalize(ray.direction * eta + nn * (eta * cos_i - cos_t));
      };
      lobes(n);
      if (!(Dot(reflected, ng) > 0) || (f < 1.0f && !(Dot(refracted, ng) < 0))) lobes(ng);
      const Vec3f tint = ray.weight * m.albedo;
      if (path_) {  // one lobe, chosen with its Fresnel probability (the weight is unchanged)
        if (rng.Uniform(ray.depth, RandomUse::kLobe) < f)
          Spawn(ray, RayType::kSpecular, OffsetRayOrigin(p, ng, p_error), reflected, tint, out);
        else
          Spawn(ray, RayType::kSpecular, OffsetRayOrigin(p, -ng, p_error), refracted, tint, out);
      } else {  // Whitted: both lobes, each while it still weighs something
        const Vec3f reflect_weight = tint * f, refract_weight = tint * (1 - f);
        if (Traced(reflect_weight)) {
          Spawn(ray, RayType::kSpecular, OffsetRayOrigin(p, ng, p_error), reflected, reflect_weight,
                out);
        }
        if (Traced(refract_weight)) {
          Spawn(ray, RayType::kSpecular, OffsetRayOrigin(p, -ng, p_error), refracted,
                refract_weight, out);
        }
      }
      break;
    }
  }
}

}  // namespace raystack::slave
