#include "slave/primary_approach.h"

#include <algorithm>
#include <cmath>

namespace raystack::slave {

PrimaryApproach::PrimaryApproach(const Bounds3f& model, Vec3f camera) : camera_(camera) {
  if (model.Empty()) return;
  double outside = 0;  // the camera's distance from the box, in double
  for (int a = 0; a < 3; ++a) {
    lower_[a] = model.lower[a];
    upper_[a] = model.upper[a];
    size_ = std::max(size_, upper_[a] - lower_[a]);
    const double c = camera[a];
    const double gap = std::max({lower_[a] - c, c - upper_[a], 0.0});
    outside += gap * gap;
  }
  // A flat or point-like model is still a model of some size for its float coordinates.
  size_ = std::max(size_, 0x1p-20 * std::max({std::fabs(lower_[0]), std::fabs(lower_[1]),
                                               std::fabs(lower_[2]), std::fabs(upper_[0]),
                                               std::fabs(upper_[1]), std::fabs(upper_[2])}));
  far_ = size_ > 0 && std::sqrt(outside) > kFarSizes * size_;
}

void PrimaryApproach::Approach(Ray* ray) const {
  if (!far_) return;
  // Along the direction's dominant axis k, to the plane two model sizes before the box's centre
  // on the camera's side: the box (at most a size across) lies wholly ahead of that plane,
  // and the ray moves monotonically along k, so what it meets is unchanged. The plane is set
  // directly, not reached by a long sum: from 1e17 away a distance along the ray, in double,
  // is off by tens of units, which moved the origin past a small model (review, 2026-11-26).
  // The other coordinates follow the ray there; their rounding moves the ray sideways by far
  // less than its float direction can tell apart at that distance, the same in every mode.
  int k = 0;
  for (int a = 1; a < 3; ++a)
    if (std::fabs(ray->direction[a]) > std::fabs(ray->direction[k])) k = a;
  const double dk = ray->direction[k];
  if (dk == 0) return;
  const double centre = 0.5 * (lower_[k] + upper_[k]);
  const double plane = centre - (dk > 0 ? 2 : -2) * size_;
  const double t = (plane - double{ray->origin[k]}) / dk;
  if (!(t > 0)) return;  // the camera is past that plane: the model is not ahead
  for (int a = 0; a < 3; ++a)
    ray->origin[a] = static_cast<float>(
        a == k ? plane : double{ray->origin[a]} + double{ray->direction[a]} * t);
}

double PrimaryApproach::Skipped(Vec3f origin) const {
  if (!far_ || origin == camera_) return 0;
  double d2 = 0;
  for (int a = 0; a < 3; ++a) {
    const double d = double{origin[a]} - double{camera_[a]};
    d2 += d * d;
  }
  return std::sqrt(d2);
}

}  // namespace raystack::slave
