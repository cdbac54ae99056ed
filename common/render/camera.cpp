#include "common/render/camera.h"

#include <cmath>
#include <numbers>

#include "common/base/check.h"

namespace raystack::render {
namespace {

struct Vec3d {
  double x, y, z;
};
Vec3d ToDouble(Vec3f v) { return {v.x, v.y, v.z}; }
Vec3d Sub(Vec3d a, Vec3d b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
Vec3d CrossD(Vec3d a, Vec3d b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
double LengthD(Vec3d a) { return std::sqrt(a.x * a.x + a.y * a.y + a.z * a.z); }
// Normalised, then to float: the frame is built in double so that neither far-apart nor
// nearly-coincident camera points overflow or underflow.
Vec3f UnitF(Vec3d a) {
  const double len = LengthD(a);
  return {static_cast<float>(a.x / len), static_cast<float>(a.y / len),
          static_cast<float>(a.z / len)};
}

}  // namespace

Camera::Camera(const CameraDesc& desc)
    : position_(desc.position), width_(desc.width), height_(desc.height) {
  CHECK(desc.width >= 1 && desc.height >= 1);
  CHECK(desc.fov_y_deg > 0 && desc.fov_y_deg < 180);
  const Vec3d view = Sub(ToDouble(desc.look_at), ToDouble(desc.position));
  const Vec3d side = CrossD(view, ToDouble(desc.up));
  CHECK(LengthD(view) > 0 && LengthD(side) > 0);
  const Vec3d forward = {view.x / LengthD(view), view.y / LengthD(view), view.z / LengthD(view)};
  const Vec3d right = {side.x / LengthD(side), side.y / LengthD(side), side.z / LengthD(side)};
  forward_ = UnitF(forward);
  right_ = UnitF(right);
  up_ = UnitF(CrossD(right, forward));

  const double tan_half = std::tan(double{desc.fov_y_deg} * std::numbers::pi / 360.0);
  half_height_ = static_cast<float>(tan_half);
  half_width_ = static_cast<float>(tan_half * desc.width / desc.height);
  scale_ = static_cast<float>(2.0 * tan_half / desc.height);
}

Ray Camera::Generate(float x, float y) const {
  const float px = x * scale_ - half_width_;
  const float py = half_height_ - y * scale_;
  Ray ray;
  ray.origin = position_;
  ray.direction = Normalize(forward_ + px * right_ + py * up_);
  return ray;
}

}  // namespace raystack::render
