// The error estimators on images whose answer is known by hand.

#include "common/render/convergence.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "common/render/film.h"

namespace raystack::render {
namespace {

image::ImageLayers Grey(int w, int h, float value, uint32_t samples, float variance) {
  image::ImageLayers im;
  im.Resize(w, h);
  for (size_t i = 0; i < im.samples.size(); ++i) {
    for (int c = 0; c < 3; ++c) im.rgba[4 * i + c] = value;
    im.samples[i] = samples;
    im.variance[i] = variance;
  }
  return im;
}

TEST(Convergence, EstimateIsTheRootMeanVarianceOfTheMean) {
  image::ImageLayers im = Grey(4, 4, 0.5f, 4, 0.01f);
  im.variance[0] = 0.09f;  // one noisy pixel
  ConvergencePoint p;
  EstimateError(im, nullptr, &p);
  EXPECT_NEAR(p.error_estimate, std::sqrt((15 * 0.01 + 0.09) / 16), 1e-6);
  EXPECT_NEAR(p.rel_error_estimate, (15 * 0.01 + 0.09) / 16 / (0.25 + kRelMseEpsilon), 1e-6);
  EXPECT_EQ(p.pixels_covered, 16u);
  EXPECT_EQ(p.min_samples, 4u);
  EXPECT_TRUE(std::isnan(p.rmse));  // no reference
}

TEST(Convergence, NoEstimateBeforeTwoSamples) {
  ConvergencePoint p;
  EstimateError(Grey(4, 4, 0.5f, 1, 0), nullptr, &p);
  EXPECT_TRUE(std::isnan(p.error_estimate));
  EXPECT_EQ(p.min_samples, 1u);
}

TEST(Convergence, RmseAgainstItselfIsZeroAndAgainstAnOffsetIsTheOffset) {
  const image::ImageLayers im = Grey(8, 4, 0.5f, 2, 0.01f);
  ConvergencePoint p;
  EstimateError(im, &im, &p);
  EXPECT_EQ(p.rmse, 0.0);
  EXPECT_EQ(p.relmse, 0.0);
  const image::ImageLayers ref = Grey(8, 4, 0.75f, 2, 0);
  EstimateError(im, &ref, &p);
  EXPECT_NEAR(p.rmse, 0.25, 1e-6);  // luminance of grey is the grey
  EXPECT_NEAR(p.relmse, 0.0625 / (0.5625 + kRelMseEpsilon), 1e-6);
}

TEST(Convergence, UncoveredPixelsTakeTheirNearestComputedAncestor) {
  image::ImageLayers im = Grey(16, 16, 0, 0, 0);
  auto set = [&](int x, int y, float v) {
    const size_t i = static_cast<size_t>(y) * 16 + x;
    for (int c = 0; c < 3; ++c) im.rgba[4 * i + c] = v;
    im.samples[i] = 1;
  };
  set(0, 0, 1.0f);
  set(8, 8, 2.0f);
  std::vector<double> y(300, 7.0);  // a caller's memory: nothing of it may remain
  FilledLuminance(im, &y);
  ASSERT_EQ(y.size(), 256u);
  EXPECT_EQ(std::count(y.begin(), y.end(), 7.0), 0);
  EXPECT_NEAR(y[5 * 16 + 3], 1.0, 1e-6);    // (3,5): ancestors (2,4), (0,4), (0,0)
  EXPECT_NEAR(y[9 * 16 + 15], 2.0, 1e-6);   // (15,9): ... (8,8)
  EXPECT_NEAR(y[12 * 16 + 3], 1.0, 1e-6);   // (3,12): (0,8) is not computed, (0,0) is
  ConvergencePoint p;
  EstimateError(im, nullptr, &p);
  EXPECT_EQ(p.pixels_covered, 2u);
  EXPECT_EQ(p.min_samples, 0u);
}

TEST(Convergence, ReferenceOfAnotherSizeNamesTheFile) {
  const Status s = CheckReference(Grey(4, 4, 0, 0, 0), 8, 4, "ref.exr");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("ref.exr"), std::string::npos);
  EXPECT_NE(s.message().find("4x4"), std::string::npos);
  EXPECT_TRUE(CheckReference(Grey(8, 4, 0, 0, 0), 8, 4, "ref.exr").ok());
}

TEST(Film, CountsSamplesBelowAPassEndAndRays) {
  Film film(2, 1);
  std::vector<SampleResult> batch;
  for (uint32_t s = 0; s < 3; ++s)
    for (uint32_t p = 0; p < 2; ++p) batch.push_back({p, s, {0.5f, 0.5f, 0.5f}, 1, {0, 0, 1}, {1, 1, 1}, 1});
  batch.pop_back();  // pixel 1 lacks its sample 2
  film.Merge(batch, 42);
  EXPECT_EQ(film.samples_below(1), 2u);
  EXPECT_EQ(film.samples_below(2), 4u);
  EXPECT_EQ(film.samples_below(3), 5u);  // not 6: the third pass has not ended
  EXPECT_EQ(film.rays_traced(), 42u);
}

}  // namespace
}  // namespace raystack::render
