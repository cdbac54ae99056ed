#include "common/render/film.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/render/scene.h"

namespace raystack::render {

// A pixel's sums hold at most one value per sample (Unmerge takes back only what was merged).
static_assert(kMaxSpp <= FixedSum::kMaxTerms, "a pixel's fixed-point sums could wrap around");

Film::Film(int width, int height)
    : width_(width),
      height_(height),
      pixels_(static_cast<size_t>(width) * height),
      z_(pixels_.size(), std::numeric_limits<float>::infinity()),
      normal_(pixels_.size() * 3, 0.0f),
      albedo_(pixels_.size() * 3, 0.0f) {}

void Film::Merge(std::span<const SampleResult> batch, uint64_t rays) {
  std::lock_guard lock(mu_);
  rays_ += rays;
  // A batch's pixels are spread over the frame (priority order): each is a cache miss. Asking
  // for them a few samples ahead lets the misses overlap instead of coming one at a time.
  // Always inlined: GCC finds a function whose only effect is prefetching free of side effects
  // and drops the calls to it (found with objdump: Merge had no prefetch instruction).
  constexpr size_t kAhead = 16;
  auto prefetch = [&](const SampleResult& s) __attribute__((always_inline)) {
    if (s.pixel >= pixels_.size()) return;
    const char* p = reinterpret_cast<const char*>(&pixels_[s.pixel]);
    __builtin_prefetch(p, 1);
    __builtin_prefetch(p + sizeof(Pixel) - 1, 1);  // a pixel may straddle two cache lines
    if (s.sample == 0) {
      __builtin_prefetch(&z_[s.pixel], 1);
      __builtin_prefetch(&normal_[3 * s.pixel], 1);
      __builtin_prefetch(&albedo_[3 * s.pixel], 1);
    }
  };
  for (size_t i = 0; i < batch.size() && i < kAhead; ++i) prefetch(batch[i]);
  for (size_t i = 0; i < batch.size(); ++i) {
    const SampleResult& s = batch[i];
    if (i + kAhead < batch.size()) prefetch(batch[i + kAhead]);
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
    if (s.sample < kTrackedSamples) {
      if (s.sample >= by_sample_.size()) by_sample_.resize(s.sample + 1, 0);
      ++by_sample_[s.sample];
    }
    if (s.sample == 0) {
      z_[s.pixel] = s.z;
      for (int c = 0; c < 3; ++c) {
        normal_[3 * s.pixel + c] = s.normal[c];
        albedo_[3 * s.pixel + c] = s.albedo[c];
      }
    }
  }
}

void Film::Unmerge(std::span<const SampleResult> batch) {
  std::lock_guard lock(mu_);
  for (const SampleResult& s : batch) {
    if (s.pixel >= pixels_.size()) continue;
    Pixel& p = pixels_[s.pixel];
    if (p.count == 0) continue;  // never merged: nothing to take back
    const bool finite = std::isfinite(s.rgb[0]) && std::isfinite(s.rgb[1]) && std::isfinite(s.rgb[2]);
    if (!finite) {
      --nonfinite_;
    } else {
      for (int c = 0; c < 3; ++c) p.rgb[c].Subtract(s.rgb[c]);
      const double y = Luminance(s.rgb[0], s.rgb[1], s.rgb[2]);
      p.luminance_squared.Subtract(y * y);
    }
    --p.count;
    if (p.count == 0) --covered_;
    p.hits -= s.hit ? 1 : 0;
    --samples_merged_;
    if (s.sample < by_sample_.size() && by_sample_[s.sample] > 0) --by_sample_[s.sample];
    if (s.sample == 0) {  // its primary-hit layers go too, until the sample is merged again
      z_[s.pixel] = std::numeric_limits<float>::infinity();
      for (int c = 0; c < 3; ++c) normal_[3 * s.pixel + c] = albedo_[3 * s.pixel + c] = 0.0f;
    }
  }
}

void Film::Clear() {
  std::lock_guard lock(mu_);
  std::fill(pixels_.begin(), pixels_.end(), Pixel{});
  std::fill(z_.begin(), z_.end(), std::numeric_limits<float>::infinity());
  std::fill(normal_.begin(), normal_.end(), 0.0f);
  std::fill(albedo_.begin(), albedo_.end(), 0.0f);
  restored_ = image::ImageLayers{};
  restored_pixels_.clear();
  samples_merged_ = rays_ = nonfinite_ = covered_ = 0;
  by_sample_.clear();
}

void Film::Restore(const image::ImageLayers& from, std::span<const uint32_t> pixels) {
  std::lock_guard lock(mu_);
  if (restored_.width == 0) restored_ = from;
  restored_pixels_.insert(restored_pixels_.end(), pixels.begin(), pixels.end());
}

uint64_t Film::pixels_restored() const {
  std::lock_guard lock(mu_);
  return restored_pixels_.size();
}

uint64_t Film::samples_merged() const {
  std::lock_guard lock(mu_);
  return samples_merged_;
}

uint64_t Film::rays_traced() const {
  std::lock_guard lock(mu_);
  return rays_;
}

uint64_t Film::samples_below(uint32_t end) const {
  std::lock_guard lock(mu_);
  uint64_t sum = 0;
  for (size_t i = 0; i < by_sample_.size() && i < end; ++i) sum += by_sample_[i];
  return sum;
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
  image::ImageLayers out;
  ResolveInto(&out);
  return out;
}

void Film::ResolveInto(image::ImageLayers* into) const {
  image::ImageLayers& out = *into;
  // Cleared before the lock is taken: on a film merging while it is measured (a convergence
  // log, one process), ray threads wait for this lock to merge their samples.
  out.Resize(width_, height_);
  std::lock_guard lock(mu_);
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
  const image::ImageLayers& r = restored_;
  for (const uint32_t i : restored_pixels_) {
    if (i >= pixels_.size()) continue;
    for (int c = 0; c < 4; ++c) out.rgba[4 * i + c] = r.rgba[4 * i + c];
    if (!r.z.empty()) out.z[i] = r.z[i];
    for (int c = 0; c < 3 && !r.normal.empty(); ++c) out.normal[3 * i + c] = r.normal[3 * i + c];
    for (int c = 0; c < 3 && !r.albedo.empty(); ++c) out.albedo[3 * i + c] = r.albedo[3 * i + c];
    if (!r.samples.empty()) out.samples[i] = r.samples[i];
    if (!r.variance.empty()) out.variance[i] = r.variance[i];
  }
}

void Film::ResolveColour(std::vector<float>* rgb, std::vector<uint32_t>* counts,
                         std::chrono::steady_clock::duration* held) const {
  if (rgb) rgb->resize(pixels_.size() * 3);
  counts->resize(pixels_.size());
  std::lock_guard lock(mu_);
  const auto start = std::chrono::steady_clock::now();
  struct Timed {  // the time under the lock, stopped as the lock is released
    std::chrono::steady_clock::time_point start;
    std::chrono::steady_clock::duration* held;
    ~Timed() {
      if (held) *held = std::chrono::steady_clock::now() - start;
    }
  } timed{start, held};
  for (size_t i = 0; i < pixels_.size(); ++i) {
    const Pixel& p = pixels_[i];
    (*counts)[i] = p.count;
    if (!rgb) continue;
    const double n = p.count;  // divided as in Resolve, so both give the same bits
    for (int c = 0; c < 3; ++c)
      (*rgb)[3 * i + static_cast<size_t>(c)] = p.count > 0 ? static_cast<float>(p.rgb[c].Value() / n) : 0.0f;
  }
  // As Resolve: a resumed run's restored pixels as the checkpoint has them (the preview showed
  // them as not computed, and its progress stopped short of 100%).
  for (const uint32_t i : restored_pixels_) {
    if (i >= pixels_.size()) continue;
    for (size_t c = 0; rgb && c < 3; ++c) (*rgb)[3 * i + c] = restored_.rgba[4 * i + c];
    (*counts)[i] = restored_.samples.empty() ? 1 : restored_.samples[i];
  }
}

uint64_t Film::samples_restored() const {
  std::lock_guard lock(mu_);
  uint64_t sum = 0;
  for (const uint32_t i : restored_pixels_)
    if (i < pixels_.size()) sum += restored_.samples.empty() ? 1 : restored_.samples[i];
  return sum;
}

}  // namespace raystack::render
