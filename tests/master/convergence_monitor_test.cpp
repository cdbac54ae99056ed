// ConvergenceMonitor: pass ends are measured while a frame renders, except the frame's last,
// which Finish measures on the image resolved for the EXR (so the film is resolved once at the
// end of a frame, outside the frame's time).

#include "master/convergence_monitor.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "common/render/film.h"
#include "common/render/frame_plan.h"

namespace raystack::master {
namespace {

constexpr int kSide = 4;

// Sample `sample` of every pixel, with a radiance that differs between pixels and samples so
// the error estimate is finite and non-zero once two samples are in.
void MergeSample(render::Film* film, uint32_t sample) {
  std::vector<render::SampleResult> batch;
  for (uint32_t p = 0; p < kSide * kSide; ++p) {
    render::SampleResult s{};
    s.pixel = p;
    s.sample = sample;
    const float v = 0.1f * static_cast<float>(p % 3) + 0.3f * static_cast<float>(sample);
    s.rgb[0] = s.rgb[1] = s.rgb[2] = v;
    s.z = 1.0f;
    s.hit = 1;
    batch.push_back(s);
  }
  film->Merge(batch, batch.size());
}

// One tile covering the frame, rendered in one sweep per pass.
render::FramePlan Passes(std::vector<render::SampleRange> passes) {
  render::FramePlan plan;
  plan.width = plan.height = kSide;
  plan.passes = std::move(passes);
  for (uint32_t p = 0; p < plan.passes.size(); ++p) {
    render::Tile tile;
    tile.x1 = tile.y1 = kSide;
    tile.sample_begin = plan.passes[p].begin;
    tile.sample_end = plan.passes[p].end;
    plan.AddSweep({tile}, p, true);
  }
  return plan;
}

TEST(ConvergenceMonitor, PollMeasuresPassEndsButLeavesTheLastToFinish) {
  render::Film film(kSide, kSide);
  const render::FramePlan plan = Passes({{0, 1}, {1, 2}});
  ConvergenceMonitor monitor(film, plan, StopRules{}, 0, nullptr, nullptr, 1.0);

  MergeSample(&film, 0);
  ASSERT_TRUE(monitor.Poll());
  EXPECT_EQ(monitor.last().samples, uint64_t{kSide * kSide});  // pass 1 measured
  EXPECT_EQ(monitor.last().min_samples, 1u);

  MergeSample(&film, 1);  // the frame's last sample: pass 2 (the last) has ended
  ASSERT_TRUE(monitor.Poll());
  EXPECT_EQ(monitor.last().samples, uint64_t{kSide * kSide})  // not measured by Poll
      << "the last pass must be left to Finish";

  monitor.Finish(film.Resolve());
  EXPECT_EQ(monitor.last().samples, uint64_t{2 * kSide * kSide});
  EXPECT_EQ(monitor.last().min_samples, 2u);
  EXPECT_TRUE(std::isfinite(monitor.last().error_estimate));
  EXPECT_GT(monitor.last().error_estimate, 0.0);
}

TEST(ConvergenceMonitor, ATargetErrorStillStopsAfterAPassBeforeTheLast) {
  render::Film film(kSide, kSide);
  // Two samples by the first pass end: an error estimate exists.
  const render::FramePlan plan = Passes({{0, 2}, {2, 4}});
  StopRules rules;
  rules.target_error = 1e9;  // any estimate meets it
  ConvergenceMonitor monitor(film, plan, rules, 0, nullptr, nullptr, 1.0);
  MergeSample(&film, 0);
  MergeSample(&film, 1);
  EXPECT_FALSE(monitor.Poll());
  EXPECT_TRUE(monitor.stopped());
}

// Passes short enough that several end between two looks: the film measured is the newest
// pass's, so the stop names that pass and what the pixels hold (it used to stop "after pass 1
// (1 samples per pixel)" with the figures of pass 3).
TEST(ConvergenceMonitor, PassesEndedBetweenLooksAreJudgedAsTheNewest) {
  render::Film film(kSide, kSide);
  const render::FramePlan plan = Passes({{0, 1}, {1, 2}, {2, 3}, {3, 4}});
  StopRules rules;
  rules.target_error = 1e9;
  ConvergenceMonitor monitor(film, plan, rules, 0, nullptr, nullptr, 1.0);
  for (uint32_t s = 0; s < 3; ++s) MergeSample(&film, s);
  EXPECT_FALSE(monitor.Poll());
  ASSERT_TRUE(monitor.stopped());
  EXPECT_NE(monitor.stop_reason().find("after pass 3 (3 samples per pixel; the fewest a pixel "
                                       "has: 3;"), std::string::npos) << monitor.stop_reason();
}

}  // namespace
}  // namespace raystack::master
