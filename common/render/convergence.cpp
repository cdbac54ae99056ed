#include "common/render/convergence.h"

#include <algorithm>
#include <cmath>

#include "common/base/log.h"
#include "common/render/film.h"

namespace raystack::render {
namespace {

double PixelLuminance(const image::ImageLayers& image, size_t i) {
  return Luminance(image.rgba[4 * i], image.rgba[4 * i + 1], image.rgba[4 * i + 2]);
}

}  // namespace

void FilledLuminance(const image::ImageLayers& image, std::vector<double>* luminance) {
  const size_t n = static_cast<size_t>(image.width) * static_cast<size_t>(image.height);
  std::vector<double>& y = *luminance;
  y.assign(n, 0.0);
  for (size_t i = 0; i < n; ++i)
    if (image.samples[i] > 0) y[i] = PixelLuminance(image, i);
  for (int py = 0; py < image.height; ++py)
    for (int px = 0; px < image.width; ++px) {
      const size_t i = static_cast<size_t>(py) * image.width + px;
      if (image.samples[i] > 0) continue;
      // Ancestors at 2, 4, 8, ... until one is computed; (0, 0) is everyone's last.
      for (int level = 1; level < 31; ++level) {
        const int mask = ~((1 << level) - 1);
        const size_t a = static_cast<size_t>(py & mask) * image.width + (px & mask);
        if (image.samples[a] > 0) {
          y[i] = y[a];
          break;
        }
        if ((px & mask) == 0 && (py & mask) == 0) break;
      }
    }
}

void EstimateError(const image::ImageLayers& image, const image::ImageLayers* reference,
                   ConvergencePoint* point, std::vector<double>* scratch, bool filled) {
  const size_t n = static_cast<size_t>(image.width) * static_cast<size_t>(image.height);
  uint64_t covered = 0, with_variance = 0;
  uint32_t min_samples = n > 0 ? image.samples[0] : 0;
  double var_sum = 0, rel_sum = 0;
  for (size_t i = 0; i < n; ++i) {
    const uint32_t count = image.samples[i];
    min_samples = std::min(min_samples, count);
    if (count > 0) ++covered;
    if (count < 2) continue;
    ++with_variance;
    const double var = image.variance[i];
    const double y = PixelLuminance(image, i);
    var_sum += var;
    rel_sum += var / (y * y + kRelMseEpsilon);
  }
  point->pixels_covered = covered;
  point->min_samples = min_samples;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  point->error_estimate = with_variance ? std::sqrt(var_sum / static_cast<double>(with_variance)) : nan;
  point->rel_error_estimate = with_variance ? rel_sum / static_cast<double>(with_variance) : nan;
  point->rmse = point->relmse = nan;
  if (!reference || n == 0) return;
  std::vector<double> own;
  std::vector<double>& y = scratch ? *scratch : own;
  if (filled) {
    FilledLuminance(image, &y);
  } else {
    y.assign(n, 0.0);
    for (size_t i = 0; i < n; ++i)
      if (image.samples[i] > 0) y[i] = PixelLuminance(image, i);
  }
  double se = 0, rel = 0;
  for (size_t i = 0; i < n; ++i) {
    const double r = PixelLuminance(*reference, i);
    const double d = y[i] - r;
    se += d * d;
    rel += d * d / (r * r + kRelMseEpsilon);
  }
  point->rmse = std::sqrt(se / static_cast<double>(n));
  point->relmse = rel / static_cast<double>(n);
}

Status CheckReference(const image::ImageLayers& reference, int width, int height,
                      const std::string& path) {
  if (reference.width != width || reference.height != height)
    return Status::Error(StrFormat("%s: the reference is %dx%d, the image %dx%d", path.c_str(),
                                   reference.width, reference.height, width, height));
  if (reference.partial)
    return Status::Error(path + ": a checkpoint (its state is partial): a reference is a finished "
                         "render (render it to the end, or give another)");
  const size_t n = static_cast<size_t>(width) * static_cast<size_t>(height);
  for (size_t i = 0; i < n && 4 * i + 2 < reference.rgba.size(); ++i)
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(reference.rgba[4 * i + c]))
        return Status::Error(StrFormat("%s: pixel (%zu, %zu) is %g: a reference must be finite",
                                       path.c_str(), i % static_cast<size_t>(width),
                                       i / static_cast<size_t>(width),
                                       double{reference.rgba[4 * i + c]}));
  if (!reference.samples.empty()) {
    const size_t unsampled = static_cast<size_t>(std::count(reference.samples.begin(), reference.samples.end(), 0u));
    if (unsampled > 0)
      LOG_WARNING("render", "%s: %zu pixels of the reference have no sample (black): the error "
                  "against them measures the reference's gaps", path.c_str(), unsampled);
  }
  return OkStatus();
}

}  // namespace raystack::render
