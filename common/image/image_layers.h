#pragma once
// (placeholder until the image library lands)
#include <cstdint>
#include <limits>
#include <vector>
namespace raystack::image {
struct ImageLayers {
  int width = 0, height = 0;
  std::vector<float> rgba, z, normal, albedo;
  std::vector<uint32_t> samples;
  std::vector<float> variance;
  void Resize(int w, int h) {
    width = w; height = h;
    const size_t n = static_cast<size_t>(w) * h;
    rgba.assign(4 * n, 0.0f); z.assign(n, std::numeric_limits<float>::infinity());
    normal.assign(3 * n, 0.0f); albedo.assign(3 * n, 0.0f); samples.assign(n, 0); variance.assign(n, 0.0f);
  }
};
}  // namespace raystack::image
