#pragma once
// Primary rays from a camera far from the model start near it.
//
// Every float test against a ray (box slabs, the triangle test's shear) works on coordinates
// relative to the ray's origin, so it errs by ulps of the origin's coordinates. From a camera
// a thousand model sizes away those ulps reach the model's detail: the box tests' safety
// margins (bvh.h, BoxMarginPads) grow past the triangles and cull nothing (a 40 x 30 frame of
// the dragon from 1e5 away took 13-22 s against 0.3 s from 1e3), and hit points are off by
// more than a light's height above a surface, whose shadow rays then start beyond the light
// (the model renders unlit). So a primary ray from such a camera starts where it crosses a
// plane two model sizes before the box's centre, across its direction's dominant axis (the
// box, at most a size across, lies wholly ahead): what the ray meets is unchanged, and every
// error is ulps of the model's coordinates. The distance skipped is added back to the hit's
// depth (Z).
//
// Cameras nearer than kFarSizes model sizes keep their origin, bit for bit.

#include "common/geometry/bounds.h"
#include "common/geometry/ray.h"
#include "common/geometry/vec.h"

namespace raystack::slave {

class PrimaryApproach {
 public:
  // A camera at kFarSizes model sizes or more from the model's box is "far".
  static constexpr double kFarSizes = 64;

  PrimaryApproach() = default;
  PrimaryApproach(const Bounds3f& model, Vec3f camera);

  // Moves a far camera's `ray` (origin at the camera) to where it crosses the plane two model
  // sizes before the box's centre across its dominant axis; leaves it be otherwise.
  void Approach(Ray* ray) const;

  // The distance from the camera to a primary ray's origin (0 when it was not moved), for the
  // hit's depth.
  double Skipped(Vec3f origin) const;

 private:
  bool far_ = false;
  Vec3f camera_;
  double lower_[3] = {}, upper_[3] = {}, size_ = 0;
};

}  // namespace raystack::slave
