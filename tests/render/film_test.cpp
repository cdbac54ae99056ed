// The film's merge is exact and order-independent, and Unmerge takes samples back exactly: a
// film that merged A and B and then unmerged B is bit for bit the film that merged only A.

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <utility>
#include <vector>

#include "common/render/film.h"

namespace raystack::render {
namespace {

std::vector<SampleResult> RandomSamples(int width, int height, int count, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> radiance(0.0f, 50.0f);
  std::vector<SampleResult> out(static_cast<size_t>(count));
  for (int i = 0; i < count; ++i) {
    SampleResult& s = out[static_cast<size_t>(i)];
    s.pixel = static_cast<uint32_t>(rng() % static_cast<uint32_t>(width * height));
    s.sample = static_cast<uint32_t>(i + 1);  // never sample 0: no primary-hit layers
    for (float& c : s.rgb) c = radiance(rng);
    s.hit = rng() & 1;
  }
  return out;
}

void ExpectSameImage(const image::ImageLayers& a, const image::ImageLayers& b) {
  ASSERT_EQ(a.rgba.size(), b.rgba.size());
  for (size_t i = 0; i < a.rgba.size(); ++i)
    ASSERT_EQ(std::memcmp(&a.rgba[i], &b.rgba[i], sizeof(float)), 0) << "rgba " << i;
  ASSERT_EQ(a.samples, b.samples);
  for (size_t i = 0; i < a.variance.size(); ++i)
    ASSERT_EQ(std::memcmp(&a.variance[i], &b.variance[i], sizeof(float)), 0) << "variance " << i;
}

TEST(Film, UnmergeTakesSamplesBackExactly) {
  const std::vector<SampleResult> kept = RandomSamples(9, 7, 400, 1);
  std::vector<SampleResult> lost = RandomSamples(9, 7, 300, 2);
  lost[5].rgb[1] = std::numeric_limits<float>::quiet_NaN();  // dropped, and its count too
  Film only_kept(9, 7), both(9, 7);
  only_kept.Merge(kept);
  // Interleaved, in pieces, as batches arrive from several ranks.
  both.Merge(std::span(lost).first(100));
  both.Merge(kept);
  both.Merge(std::span(lost).subspan(100));
  EXPECT_NE(both.samples_merged(), only_kept.samples_merged());
  both.Unmerge(lost);
  EXPECT_EQ(both.samples_merged(), only_kept.samples_merged());
  EXPECT_EQ(both.pixels_covered(), only_kept.pixels_covered());
  EXPECT_EQ(both.nonfinite_dropped(), 0u);
  ExpectSameImage(both.Resolve(), only_kept.Resolve());
}

TEST(Film, UnmergingEverythingLeavesAnEmptyFilm) {
  const std::vector<SampleResult> all = RandomSamples(5, 5, 200, 3);
  Film film(5, 5), empty(5, 5);
  film.Merge(all);
  film.Unmerge(all);
  EXPECT_EQ(film.samples_merged(), 0u);
  EXPECT_EQ(film.pixels_covered(), 0u);
  ExpectSameImage(film.Resolve(), empty.Resolve());
}

// A cleared film is a new film: the next frame's samples give the same image, layers and
// counts in a film reused from a frame before (restored pixels, NaN drops and sample-0 layers
// included) as in a fresh one.
TEST(Film, AClearedFilmIsANewFilm) {
  std::vector<SampleResult> before = RandomSamples(9, 7, 400, 4);
  before[3].sample = 0;  // primary-hit layers
  before[3].z = 2.5f;
  before[3].normal[1] = 1.0f;
  before[3].albedo[0] = 0.5f;
  before[7].rgb[0] = std::numeric_limits<float>::quiet_NaN();  // dropped and counted
  Film reused(9, 7);
  reused.Merge(before, 1234);
  image::ImageLayers checkpoint = reused.Resolve();
  const uint32_t restored[] = {0, 1, 2};
  reused.Restore(checkpoint, restored);
  reused.Clear();
  EXPECT_EQ(reused.samples_merged(), 0u);
  EXPECT_EQ(reused.rays_traced(), 0u);
  EXPECT_EQ(reused.pixels_covered(), 0u);
  EXPECT_EQ(reused.pixels_restored(), 0u);
  EXPECT_EQ(reused.nonfinite_dropped(), 0u);
  EXPECT_EQ(reused.samples_below(1000), 0u);

  const std::vector<SampleResult> next = RandomSamples(9, 7, 300, 5);
  Film fresh(9, 7);
  reused.Merge(next, 77);
  fresh.Merge(next, 77);
  EXPECT_EQ(reused.samples_merged(), fresh.samples_merged());
  EXPECT_EQ(reused.rays_traced(), fresh.rays_traced());
  EXPECT_EQ(reused.pixels_covered(), fresh.pixels_covered());
  EXPECT_EQ(reused.samples_below(200), fresh.samples_below(200));
  const image::ImageLayers a = reused.Resolve(), b = fresh.Resolve();
  ExpectSameImage(a, b);
  ASSERT_EQ(a.z.size(), b.z.size());
  EXPECT_EQ(std::memcmp(a.z.data(), b.z.data(), a.z.size() * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(a.normal.data(), b.normal.data(), a.normal.size() * sizeof(float)), 0);
  EXPECT_EQ(std::memcmp(a.albedo.data(), b.albedo.data(), a.albedo.size() * sizeof(float)), 0);
}

// The master resolves each frame into the layers of the frame written before it: whatever they
// held (another frame, another size), the result is the film's image bit for bit.
TEST(Film, ResolvingIntoAnEarlierImageGivesTheFilmsImage) {
  std::vector<SampleResult> samples = RandomSamples(9, 7, 300, 6);
  samples[5].sample = 0;
  samples[5].z = 4.5f;
  samples[5].normal[2] = 1.0f;
  Film film(9, 7);
  film.Merge(samples, 50);
  for (const auto& [w, h] : {std::pair{9, 7}, std::pair{20, 11}, std::pair{3, 2}}) {
    Film other(w, h);
    other.Merge(RandomSamples(w, h, 500, 7), 10);
    image::ImageLayers earlier = other.Resolve();
    film.ResolveInto(&earlier);
    const image::ImageLayers fresh = film.Resolve();
    EXPECT_EQ(earlier.width, 9);
    EXPECT_EQ(earlier.height, 7);
    ExpectSameImage(earlier, fresh);
    ASSERT_EQ(earlier.z.size(), fresh.z.size());
    EXPECT_EQ(std::memcmp(earlier.z.data(), fresh.z.data(), fresh.z.size() * sizeof(float)), 0);
    EXPECT_EQ(earlier.normal, fresh.normal);
    EXPECT_EQ(earlier.albedo, fresh.albedo);
  }
}

// A sample 0 taken back takes its pixel's primary-hit layers (Z, normal, albedo) with it: a
// frame stopped before the tile comes back must not show a lost slave's hit.
TEST(Film, UnmergingSampleZeroClearsThePrimaryHitLayers) {
  SampleResult s{};
  s.pixel = 3;
  s.sample = 0;
  s.rgb[0] = s.rgb[1] = s.rgb[2] = 0.5f;
  s.hit = true;
  s.z = 2.5f;
  s.normal[1] = 1.0f;
  s.albedo[0] = s.albedo[1] = s.albedo[2] = 0.7f;
  Film film(3, 2), empty(3, 2);
  film.Merge(std::span(&s, 1));
  EXPECT_EQ(film.Resolve().z[3], 2.5f);
  film.Unmerge(std::span(&s, 1));
  const image::ImageLayers back = film.Resolve(), none = empty.Resolve();
  EXPECT_EQ(back.z, none.z);
  EXPECT_EQ(back.normal, none.normal);
  EXPECT_EQ(back.albedo, none.albedo);
}

}  // namespace
}  // namespace raystack::render
