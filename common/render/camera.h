#pragma once
// The pinhole camera: raster position to primary ray. Immutable after construction, so one
// Camera may be shared by every thread of a render.

#include "common/geometry/ray.h"
#include "common/geometry/vec.h"
#include "common/render/scene.h"

namespace raystack::render {

class Camera {
 public:
  // `desc` must be valid as LoadScene checks it (width and height >= 1, fov in (0, 180),
  // position != look_at, up not parallel to the view direction); a CHECK fails otherwise, since
  // descriptions from files have been validated and any other is a programming error.
  explicit Camera(const CameraDesc& desc);

  // Pinhole ray through raster point (x, y): x in [0, width) to the right, y in [0, height)
  // downwards; pixel (i, j)'s centre is (i + 0.5, j + 0.5). Origin = position, direction
  // normalised, tmin 0, tmax inf. The vertical field of view spans the image height; pixels are
  // square, so the horizontal one follows from the aspect ratio.
  Ray Generate(float x, float y) const;

  int width() const { return width_; }
  int height() const { return height_; }

  // The orthonormal camera frame (right-handed: right = forward x up), for tests and for
  // engines that need it (e.g. to project a point back to the raster).
  Vec3f position() const { return position_; }
  Vec3f forward() const { return forward_; }
  Vec3f right() const { return right_; }
  Vec3f up() const { return up_; }

 private:
  Vec3f position_;
  Vec3f forward_, right_, up_;
  // Raster to the image plane at distance 1: plane = (x * scale_ - half_width_,
  // half_height_ - y * scale_).
  float scale_ = 0, half_width_ = 0, half_height_ = 0;
  int width_ = 0, height_ = 0;
};

}  // namespace raystack::render
