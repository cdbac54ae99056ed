#include "common/image/image_layers.h"

#include <limits>

#include "common/base/check.h"

namespace raystack::image {

void ImageLayers::Resize(int w, int h) {
  CHECK(w >= 0 && h >= 0);
  width = w;
  height = h;
  const size_t n = pixel_count();
  // assign, not resize: every layer starts from its fill value, whatever it held before.
  rgba.assign(4 * n, 0.0f);
  z.assign(n, std::numeric_limits<float>::infinity());
  normal.assign(3 * n, 0.0f);
  albedo.assign(3 * n, 0.0f);
  samples.assign(n, 0u);
  variance.assign(n, 0.0f);
}

}  // namespace raystack::image
