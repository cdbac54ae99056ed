#pragma once
// The image being formed: per pixel, order-independent sums of the samples' radiance and of
// its square (for the variance of the mean), the sample count, and the primary-hit layers
// (Z, normal, albedo) from each pixel's sample 0. Merging is exact integer arithmetic, so the
// same samples give the same bits in any order, from any number of threads or ranks.

#include <chrono>
#include <cstdint>
#include <mutex>
#include <span>
#include <vector>

#include "common/base/populate.h"
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
  // stored: a NaN must not reach a pixel. `rays`: the rays traced for them (for the figures).
  void Merge(std::span<const SampleResult> batch, uint64_t rays = 0);
  // Takes merged samples back out, exactly (the sums are integers): the film is then bit for
  // bit as if they had never been merged, but for the Z/normal/albedo of a sample 0, which the
  // sample's re-render writes again with the same values. For the samples of a lost slave's
  // unfinished tiles, which another slave renders again. Thread-safe.
  void Unmerge(std::span<const SampleResult> batch);

  // --resume: pixels a checkpoint already holds finished (every sample rendered) are taken as
  // the checkpoint has them, layer by layer, and Resolve gives them back verbatim: so the image
  // of a resumed run equals an uninterrupted run's bit for bit. `from` must be this film's size.
  void Restore(const image::ImageLayers& from, std::span<const uint32_t> pixels);
  uint64_t pixels_restored() const;
  // The samples the restored pixels hold (their sample counts), for progress.
  uint64_t samples_restored() const;

  // Back to the state of a new film of the same size (no sample, nothing restored). Between
  // frames of one size: a new film is ~55 MB touched for the first time (960x540: ~20 ms of
  // page faults, while every slave waits for the next frame); clearing memory that is
  // already mapped costs a few milliseconds. Thread-safe.
  void Clear();

  uint64_t samples_merged() const;
  uint64_t rays_traced() const;
  // Samples merged whose index is below `end`: equal to width * height * end exactly when
  // every pixel has its samples [0, end), i.e. a progressive pass has ended.
  uint64_t samples_below(uint32_t end) const;
  uint64_t nonfinite_dropped() const;
  // Pixels with at least one sample.
  uint64_t pixels_covered() const;

  // The current image: mean radiance, coverage alpha, Z/normal/albedo, counts and the
  // variance of the mean (luminance). Thread-safe.
  image::ImageLayers Resolve() const;
  // The same into `out`, whose layers' memory is used again where large enough (an image
  // written earlier: new memory costs a page fault a page, see ImageLayers::Resize).
  void ResolveInto(image::ImageLayers* out) const;
  // Only the mean radiance (3 floats per pixel, 0 without samples) and the sample counts
  // (restored pixels as Resolve gives them), into the caller's buffers (resized): the light copy the live preview takes several times a
  // second, holding the lock far shorter than Resolve. Thread-safe.
  // `held` (optional): how long the film's lock was held, the copy without the allocation.
  // `rgb` null: the counts alone (/status.json's tiles in flight).
  void ResolveColour(std::vector<float>* rgb, std::vector<uint32_t>* counts,
                     std::chrono::steady_clock::duration* held = nullptr) const;

 private:
  struct Pixel {
    FixedSum rgb[3];
    FixedSum luminance_squared;
    uint32_t count = 0;
    uint32_t hits = 0;
  };
  int width_, height_;
  mutable std::mutex mu_;
  // Written whole when made: mapped in one call (PopulatedAllocator), a new film costs no page
  // fault per 4 KB.
  template <typename T>
  using Pages = std::vector<T, PopulatedAllocator<T>>;
  Pages<Pixel> pixels_;
  Pages<float> z_, normal_, albedo_;
  image::ImageLayers restored_;  // empty unless Restore was called
  std::vector<uint32_t> restored_pixels_;
  uint64_t samples_merged_ = 0;
  uint64_t rays_ = 0;
  std::vector<uint64_t> by_sample_;  // samples merged per sample index (up to kTrackedSamples)
  static constexpr uint32_t kTrackedSamples = 1 << 20;
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
  void Consume(std::span<const SampleResult> batch, uint64_t rays) override {
    film_->Merge(batch, rays);
  }

 private:
  Film* film_;
};

}  // namespace raystack::render
