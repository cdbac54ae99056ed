#include "common/render/film.h"

#include <cmath>
#include <limits>

namespace raystack::render {

Film::Film(int width, int height)
    : width_(width),
      height_(height),
      pixels_(static_cast<size_t>(width) * height),
      z_(pixels_.size(), std::numeric_limits<float>::infinity()),
      normal_(pixels_.size() * 3, 0.0f),
      albedo_(pixels_.size() * 3, 0.0f) {}

void Film::Merge(std::span<const SampleResult> batch) {
  std::lock_guard lock(mu_);
  for (const SampleResult& s : batch) {
    if (s.pixel >= pixels_.size()) continue;  // callers validate; never write out of bounds
    Pixel& p = pixels_[s.pixel];
    const bool finite = std::isfinite(s.rgb[0]) && std::isfinite(s.rgb[1]) && std::isfinite(s.rgb[2]);
    if (!finite) {
      ++nonfinite_;
    } else {
      for (int c = 0; c < 3; ++c) p.rgb[c].Add(s.rgb[c]);
      const double y = Luminance(s.rgb[0], s.rgb[1], s.rgb[2]);
      p.luminance_squared.Add(y * y);
    }
    if (p.count == 0) ++covered_;
    ++p.count;
    p.hits += s.hit ? 1 : 0;
    ++samples_merged_;
    if (s.sample == 0) {
      z_[s.pixel] = s.z;
      for (int c = 0; c < 3; ++c) {
        normal_[3 * s.pixel + c] = s.normal[c];
        albedo_[3 * s.pixel + c] = s.albedo[c];
      }
    }
  }
}

uint64_t Film::samples_merged() const {
  std::lock_guard lock(mu_);
  return samples_merged_;
}

uint64_t Film::nonfinite_dropped() const {
  std::lock_guard lock(mu_);
  return nonfinite_;
}

uint64_t Film::pixels_covered() const {
  std::lock_guard lock(mu_);
  return covered_;
}

image::ImageLayers Film::Resolve() const {
  std::lock_guard lock(mu_);
  image::ImageLayers out;
  out.Resize(width_, height_);
  for (size_t i = 0; i < pixels_.size(); ++i) {
    const Pixel& p = pixels_[i];
    out.samples[i] = p.count;
    out.z[i] = z_[i];
    for (int c = 0; c < 3; ++c) {
      out.normal[3 * i + c] = normal_[3 * i + c];
      out.albedo[3 * i + c] = albedo_[3 * i + c];
    }
    if (p.count == 0) continue;
    const double n = p.count;
    double mean[3];
    for (int c = 0; c < 3; ++c) {
      mean[c] = p.rgb[c].Value() / n;
      out.rgba[4 * i + c] = static_cast<float>(mean[c]);
    }
    out.rgba[4 * i + 3] = static_cast<float>(p.hits / n);
    // Variance of the mean: the sample variance of luminance over n.
    if (p.count > 1) {
      const double y = Luminance(mean[0], mean[1], mean[2]);
      const double var = (p.luminance_squared.Value() / n - y * y) * n / (n - 1);
      out.variance[i] = static_cast<float>(std::max(0.0, var) / n);
    }
  }
  return out;
}

void Film::ResolveColour(std::vector<float>* rgb, std::vector<uint32_t>* counts) const {
  rgb->resize(pixels_.size() * 3);
  counts->resize(pixels_.size());
  std::lock_guard lock(mu_);
  for (size_t i = 0; i < pixels_.size(); ++i) {
    const Pixel& p = pixels_[i];
    (*counts)[i] = p.count;
    const double n = p.count;  // divided as in Resolve, so both give the same bits
    for (int c = 0; c < 3; ++c)
      (*rgb)[3 * i + static_cast<size_t>(c)] = p.count > 0 ? static_cast<float>(p.rgb[c].Value() / n) : 0.0f;
  }
}

}  // namespace raystack::render
