#pragma once
// How far a render is from converged, measured while it runs: the figures one line of a
// convergence log holds (and the preview shows), and the estimators behind them.
//
// Everything is computed on luminance Y (Rec. 709), the scalar the film's variance is kept for.
// - error_estimate: sqrt(mean over pixels of Var[mean]), an estimate of the RMSE against the
//   converged image that needs no reference: the film keeps per pixel the sample variance of
//   Y over n samples, divided by n (the variance of the pixel's mean). Averaged over the pixels
//   with at least 2 samples (a variance needs two); `min_samples` says whether that is all.
// - rel_error_estimate: mean over those pixels of Var[mean] / (Y^2 + 0.01), the same for the
//   relative MSE (the usual relMSE, whose 0.01 keeps dark pixels from dominating).
// - rmse, relmse: against a reference image, over every pixel: sqrt(mean (Y - Yref)^2) and
//   mean (Y - Yref)^2 / (Yref^2 + 0.01). A pixel with no sample yet takes the value of its
//   nearest computed quadtree ancestor (thesis Fig. VI.11: the pixel at its coordinates
//   rounded down to 2, 4, 8, ...), or 0 if there is none, as a viewer would see it.

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/image/image_layers.h"

namespace raystack::render {

inline constexpr double kRelMseEpsilon = 0.01;

struct ConvergencePoint {
  double seconds = 0;           // since the frame started
  uint64_t rays = 0;            // rays traced (all types)
  uint64_t samples = 0;         // samples merged into the film
  uint64_t pixels_covered = 0;  // pixels with at least one sample
  uint32_t min_samples = 0;     // the fewest samples any pixel has
  double error_estimate = std::numeric_limits<double>::quiet_NaN();
  double rel_error_estimate = std::numeric_limits<double>::quiet_NaN();
  double rmse = std::numeric_limits<double>::quiet_NaN();    // NaN: no reference
  double relmse = std::numeric_limits<double>::quiet_NaN();
};

// Fills pixels_covered, min_samples and the error figures from a resolved film (counts and
// variance layers); rmse and relmse only when `reference` is given (same size: checked by
// CheckReference first).
// `scratch` (optional): memory for the image's luminance, kept by a caller that measures often.
// `filled`: pixels without a sample count as the preview shows them (their nearest computed
// ancestor's value), else as the image file has them (black).
void EstimateError(const image::ImageLayers& image, const image::ImageLayers* reference,
                   ConvergencePoint* point, std::vector<double>* scratch = nullptr,
                   bool filled = true);

// Luminance per pixel into *y (resized), pixels without samples filled from their nearest
// computed ancestor.
void FilledLuminance(const image::ImageLayers& image, std::vector<double>* y);

// An error naming `path` unless `reference` is width x height, finished (not a checkpoint) and
// finite (a NaN pixel emptied every error column without a word; a checkpoint was measured
// against as if its unrendered pixels were black; a researcher). Pixels it has without a sample
// are a warning.
Status CheckReference(const image::ImageLayers& reference, int width, int height,
                      const std::string& path);

}  // namespace raystack::render
