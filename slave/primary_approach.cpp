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
  // To two model sizes before the point of the ray nearest the box's centre: the box (half a
  // diagonal, under a size, around the centre) lies wholly ahead, so what the ray meets is
  // unchanged, and a ray that misses the model starts near it too (from the camera, its walk's
  // margins, ulps of the camera's coordinates, took in a hundred blocks it passes by).
  double along = 0;
  for (int a = 0; a < 3; ++a)
    along += (0.5 * (lower_[a] + upper_[a]) - double{ray->origin[a]}) * double{ray->direction[a]};
  const double skip = along - 2 * size_;
  if (!(skip > 0)) return;
  for (int a = 0; a < 3; ++a)
    ray->origin[a] = static_cast<float>(double{ray->origin[a]} + double{ray->direction[a]} * skip);
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
