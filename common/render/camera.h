#pragma once
// (placeholder until the scene library lands)
#include <cmath>
#include "common/geometry/ray.h"
#include "common/render/scene.h"
namespace raystack::render {
class Camera {
 public:
  explicit Camera(const CameraDesc& d) : d_(d) {
    forward_ = Normalize(d.look_at - d.position);
    right_ = Normalize(Cross(forward_, d.up));
    up_ = Cross(right_, forward_);
    const float h = std::tan(d.fov_y_deg * 3.14159265f / 360.0f);
    scale_ = 2.0f * h / static_cast<float>(d.height);
  }
  Ray Generate(float x, float y) const {
    const float sx = (x - 0.5f * static_cast<float>(d_.width)) * scale_;
    const float sy = (0.5f * static_cast<float>(d_.height) - y) * scale_;
    Ray r; r.origin = d_.position; r.direction = Normalize(forward_ + right_ * sx + up_ * sy);
    return r;
  }
  int width() const { return d_.width; }
  int height() const { return d_.height; }
 private:
  CameraDesc d_; Vec3f forward_, right_, up_; float scale_;
};
}  // namespace raystack::render
