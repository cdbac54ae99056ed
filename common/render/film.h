#pragma once
// The image being formed: per pixel, order-independent sums of the samples' radiance and of
// its square (for the variance of the mean), the sample count, and the primary-hit layers
// (Z, normal, albedo) from each pixel's sample 0. Merging is exact integer arithmetic, so the
// same samples give the same bits in any order, from any number of threads or ranks.

#include <cstdint>
#include <mutex>
#include <span>
#include <vector>

#include "common/image/image_layers.h"
#include "common/render/fixed_sum.h"
#include "common/render/sample_result.h"

namespace raystack::render {

class Film {
 public:
  Film(int width, int height);

  int width() const { return width_; }
  int height() const { return height_; }

  // Merges finished samples (thread-safe). Non-finite radiance is dropped and counted, never
  // stored: a NaN must not reach a pixel.
  void Merge(std::span<const SampleResult> batch);

  uint64_t samples_merged() const;
  uint64_t nonfinite_dropped() const;
  // Pixels with at least one sample.
  uint64_t pixels_covered() const;

  // The current image: mean radiance, coverage alpha, Z/normal/albedo, counts and the
  // variance of the mean (luminance). Thread-safe.
  image::ImageLayers Resolve() const;
  // Only the mean radiance (3 floats per pixel, 0 without samples) and the sample counts, into
  // the caller's buffers (resized): the light copy the live preview takes several times a
  // second, holding the lock far shorter than Resolve. Thread-safe.
  void ResolveColour(std::vector<float>* rgb, std::vector<uint32_t>* counts) const;

 private:
  struct Pixel {
    FixedSum rgb[3];
    FixedSum luminance_squared;
    uint32_t count = 0;
    uint32_t hits = 0;
  };
  int width_, height_;
  mutable std::mutex mu_;
  std::vector<Pixel> pixels_;
  std::vector<float> z_, normal_, albedo_;
  uint64_t samples_merged_ = 0;
  uint64_t nonfinite_ = 0;
  uint64_t covered_ = 0;
};

// Rec. 709 luminance, the scalar the variance estimate is computed on.
inline double Luminance(double r, double g, double b) {
  return 0.2126 * r + 0.7152 * g + 0.0722 * b;
}

// A SampleSink that merges straight into a Film (one-process rendering).
class FilmSink final : public SampleSink {
 public:
  explicit FilmSink(Film* film) : film_(film) {}
  void Consume(std::span<const SampleResult> batch) override { film_->Merge(batch); }

 private:
  Film* film_;
};

}  // namespace raystack::render
