// `raystack render`'s stop rules and convergence log, run as a user runs them: --spp is
// respected exactly, --time-limit stops early and leaves a valid image, --target-error stops
// before the last pass on an easy scene, and the log's rows are monotonic, add up, and give
// RMSE 0 against a reference that is the same render.

#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "common/image/exr_io.h"
#include "common/render/film.h"
#include "tests/prep/run_process.h"
#include "tests/support/convergence_csv.h"
#include "tests/support/store_dir_fixture.h"

namespace raystack::testing {
namespace {

using prep::testing::ProcessResult;
using prep::testing::RunProcess;

const std::string& kRaystack = kRaystackBinary;
constexpr int kWidth = 48, kHeight = 32;

class ProgressiveCli : public StoreDirFixture {
 protected:
  void SetUp() override { MakeStore("spheres:20000"); }

  std::string Scene(int spp) {
    const std::string path = dir_->File("scene.json");
    std::ofstream(path) << R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 48, "height": 32 },
      "lights": [ { "type": "point", "position": [3, 8, 4], "intensity": [100, 100, 100] } ],
      "background": [0.3, 0.3, 0.4],
      "integrator": { "type": "path", "max_depth": 3, "spp": )" << spp << R"(, "seed": 3 },
      "output": "out.exr" })";
    return path;
  }

  ProcessResult Render(int spp, std::vector<std::string> extra) {
    std::vector<std::string> argv = {kRaystack, "render", Scene(spp), "--threads", "2",
                                     "--cache-mb", "1", "--no-png", "--tile-size", "16"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    return RunProcess(argv, dir_->path());
  }

  image::ImageLayers Image(const std::string& name = "out.exr") {
    Expected<image::ImageLayers> im = image::ReadExr(dir_->File(name));
    EXPECT_TRUE(im.ok()) << im.status().message();
    return im.ok() ? std::move(*im) : image::ImageLayers{};
  }
};

TEST_F(ProgressiveCli, SppOverridesTheSceneExactly) {
  const ProcessResult r = Render(1, {"--spp", "5", "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const image::ImageLayers im = Image();
  ASSERT_EQ(im.samples.size(), static_cast<size_t>(kWidth * kHeight));
  for (uint32_t n : im.samples) ASSERT_EQ(n, 5u);
}

TEST_F(ProgressiveCli, LogRowsAreMonotonicAndAddUp) {
  const ProcessResult r =
      Render(8, {"--convergence-log", dir_->File("log.csv"), "--log-interval", "0.01", "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::vector<LogRow> rows = ReadConvergenceLog(dir_->File("log.csv"));
  ASSERT_GE(rows.size(), 5u);
  const uint64_t pixels = kWidth * kHeight;
  std::vector<uint32_t> passes;
  for (size_t i = 0; i < rows.size(); ++i) {
    const LogRow& row = rows[i];
    EXPECT_EQ(row.frame, 0u);
    EXPECT_GE(row.rays, row.samples);  // a sample is at least its primary ray
    EXPECT_LE(row.pixels_covered, pixels);
    if (i > 0) {
      EXPECT_GE(row.seconds, rows[i - 1].seconds);
      EXPECT_GE(row.samples, rows[i - 1].samples);
      EXPECT_GE(row.rays, rows[i - 1].rays);
    }
    if (row.event == "pass") {  // written when noticed: by then later passes may be done too
      passes.push_back(row.pass);
      const uint32_t end = 1u << (row.pass - 1);  // passes end at 1, 2, 4, 8 samples
      EXPECT_GE(row.min_samples, end);
      EXPECT_GE(row.samples, pixels * end);
      EXPECT_EQ(row.pixels_covered, pixels);
    }
  }
  EXPECT_EQ(passes, (std::vector<uint32_t>{1, 2, 3, 4}));
  const LogRow& end = rows.back();
  EXPECT_EQ(end.event, "end");
  EXPECT_EQ(end.samples, pixels * 8);
  EXPECT_EQ(end.min_samples, 8u);
  EXPECT_TRUE(std::isfinite(end.error_estimate));
  EXPECT_GT(end.error_estimate, 0);
  EXPECT_TRUE(std::isnan(end.rmse));  // no reference
}

TEST_F(ProgressiveCli, RmseAgainstTheSameRenderIsZero) {
  ASSERT_EQ(Render(4, {"--output", dir_->File("ref.exr"), "-q"}).exit_code, 0);
  const ProcessResult r = Render(4, {"--convergence-log", dir_->File("log.csv"), "--reference",
                                     dir_->File("ref.exr"), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::vector<LogRow> rows = ReadConvergenceLog(dir_->File("log.csv"));
  ASSERT_FALSE(rows.empty());
  EXPECT_EQ(rows.back().rmse, 0.0);
  EXPECT_EQ(rows.back().relmse, 0.0);
}

TEST_F(ProgressiveCli, TimeLimitStopsEarlyAndLeavesAValidImage) {
  // Far more samples than the limit allows: only the rule can end this render.
  const ProcessResult r = Render(65535, {"--time-limit", "0.5", "--convergence-log",
                                         dir_->File("log.csv")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("stopped: --time-limit"), std::string::npos) << r.out;
  const image::ImageLayers im = Image();
  uint64_t total = 0;
  for (size_t i = 0; i < im.samples.size(); ++i) {
    total += im.samples[i];
    if (im.samples[i] == 0) continue;
    for (int c = 0; c < 3; ++c) ASSERT_TRUE(std::isfinite(im.rgba[4 * i + c]));
  }
  EXPECT_GT(total, 0u);
  EXPECT_LT(total, uint64_t{kWidth * kHeight} * 65535);
  // The EXR says it was stopped, and why (found by a researcher: its provenance said spp 65535,
  // its state complete, and only the samples layer told otherwise).
  EXPECT_FALSE(im.partial);
  EXPECT_NE(im.stopped.find("--time-limit"), std::string::npos) << im.stopped;
  const std::vector<LogRow> rows = ReadConvergenceLog(dir_->File("log.csv"));
  ASSERT_GE(rows.size(), 2u);
  EXPECT_EQ(rows[rows.size() - 2].event, "stop");
  EXPECT_EQ(rows.back().samples, total);  // the image holds every sample merged
  // The reason says the frame's final count, which the tiles in flight when the limit came
  // raised (found by an operator: the stop line's count and the frame's disagreed).
  const std::string final_count = std::to_string(total);
  EXPECT_TRUE(im.stopped.find(", " + final_count + " once the tiles then in flight were finished") !=
                  std::string::npos ||
              im.stopped.find("with " + final_count + " of ") != std::string::npos)
      << im.stopped << " (final count " << final_count << ")";
}

// Found by a researcher: a frame stopped before its first pass covered it logged an "end" RMSE
// of 0.64 where its file scored 0.95: the rows measure the image as the preview shows it (pixels
// without a sample as their nearest computed ancestor), the file has them black. The end row is
// the file's; the run says the pixels are missing. And --reference refuses a checkpoint and a
// non-finite pixel (which emptied every RMSE column without a word).
TEST_F(ProgressiveCli, TheLogsEndRowIsTheImageAsWrittenAndTheReferenceIsChecked) {
  std::ofstream(dir_->File("big.json")) << R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 320, "height": 240 },
      "lights": [ { "type": "point", "position": [3, 8, 4], "intensity": [100, 100, 100] } ],
      "background": [0.3, 0.3, 0.4],
      "integrator": { "type": "path", "max_depth": 3, "spp": 2, "seed": 3 } })";
  const std::vector<std::string> common = {kRaystack, "render", dir_->File("big.json"), "--threads",
                                           "1", "--cache-mb", "1", "--no-png"};
  auto run = [&](std::vector<std::string> extra) {
    std::vector<std::string> argv = common;
    argv.insert(argv.end(), extra.begin(), extra.end());
    return RunProcess(argv, dir_->path());
  };
  ASSERT_EQ(run({"--output", dir_->File("ref.exr")}).exit_code, 0);
  const ProcessResult r = run({"--output", dir_->File("cut.exr"), "--spp", "4096", "--time-limit",
                               "0.003", "--convergence-log", dir_->File("cut.csv"), "--reference",
                               dir_->File("ref.exr")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const image::ImageLayers cut = Image("cut.exr"), ref = Image("ref.exr");
  double se = 0;
  size_t unsampled = 0;
  for (size_t i = 0; i < cut.samples.size(); ++i) {
    unsampled += cut.samples[i] == 0;
    const double d = render::Luminance(cut.rgba[4 * i], cut.rgba[4 * i + 1], cut.rgba[4 * i + 2]) -
                     render::Luminance(ref.rgba[4 * i], ref.rgba[4 * i + 1], ref.rgba[4 * i + 2]);
    se += d * d;
  }
  const std::vector<LogRow> rows = ReadConvergenceLog(dir_->File("cut.csv"));
  ASSERT_FALSE(rows.empty());
  ASSERT_EQ(rows.back().event, "end");
  EXPECT_NEAR(rows.back().rmse, std::sqrt(se / static_cast<double>(cut.samples.size())), 1e-6);
  if (unsampled > 0) {
    EXPECT_NE(r.err.find(std::to_string(unsampled) + " pixels have no sample"), std::string::npos) << r.err;
  }

  // The reference: a checkpoint, then a NaN pixel.
  image::ImageLayers bad = ref;
  bad.partial = true;
  ASSERT_TRUE(image::WriteExr(dir_->File("bad.exr"), bad).ok());
  const std::vector<std::string> against = {"--output", dir_->File("x.exr"), "--convergence-log",
                                            dir_->File("x.csv"), "--reference", dir_->File("bad.exr")};
  ProcessResult refused = run(against);
  EXPECT_EQ(refused.exit_code, 1);
  EXPECT_NE(refused.err.find("bad.exr: a checkpoint"), std::string::npos) << refused.err;
  bad.partial = false;
  bad.rgba[4 * (5 * 320 + 7) + 1] = std::nanf("");
  ASSERT_TRUE(image::WriteExr(dir_->File("bad.exr"), bad).ok());
  refused = run(against);
  EXPECT_EQ(refused.exit_code, 1);
  EXPECT_NE(refused.err.find("bad.exr: pixel (7, 5) is nan: a reference must be finite"),
            std::string::npos) << refused.err;
}

TEST_F(ProgressiveCli, TargetErrorStopsBeforeTheLastPass) {
  // The error at 4 samples per pixel, then a target half of it: about 16 samples reach it
  // (the error falls as 1/sqrt(n)), far fewer than the 1024 allowed.
  ASSERT_EQ(Render(4, {"--convergence-log", dir_->File("log4.csv"), "-q"}).exit_code, 0);
  const double e4 = ReadConvergenceLog(dir_->File("log4.csv")).back().error_estimate;
  ASSERT_GT(e4, 0);
  const ProcessResult r = Render(1024, {"--target-error", std::to_string(e4 / 2),
                                        "--convergence-log", dir_->File("log.csv")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("stopped: --target-error"), std::string::npos) << r.out;
  const std::vector<LogRow> rows = ReadConvergenceLog(dir_->File("log.csv"));
  const LogRow* stop = nullptr;
  for (const LogRow& row : rows)
    if (row.event == "stop") stop = &row;
  ASSERT_NE(stop, nullptr);
  EXPECT_LE(stop->error_estimate, e4 / 2);
  EXPECT_LT(stop->min_samples, 1024u);
  EXPECT_GE(stop->min_samples, 8u);
  const image::ImageLayers im = Image();
  for (uint32_t n : im.samples) ASSERT_LT(n, 1024u);
}

TEST_F(ProgressiveCli, BadOptionsAndReferencesAreClearErrors) {
  ASSERT_EQ(Render(1, {"--output", dir_->File("small.exr"), "-q"}).exit_code, 0);
  {
    std::ofstream(dir_->File("other.json")) << R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 20, "height": 10 },
      "output": "other.exr" })";
    const ProcessResult r = RunProcess({kRaystack, "render", dir_->File("other.json"), "--reference",
                                        dir_->File("small.exr"), "--convergence-log",
                                        dir_->File("log.csv"), "-q"}, dir_->path());
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_NE(r.err.find("small.exr"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("48x32"), std::string::npos) << r.err;
  }
  {
    const ProcessResult r = Render(1, {"--reference", dir_->File("missing.exr"),
                                       "--convergence-log", dir_->File("log.csv"), "-q"});
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_NE(r.err.find("missing.exr"), std::string::npos) << r.err;
  }
  EXPECT_EQ(Render(1, {"--pixel-order", "spiral"}).exit_code, 2);
  EXPECT_EQ(Render(1, {"--time-limit", "-1"}).exit_code, 2);
  EXPECT_EQ(Render(1, {"--target-error", "nan"}).exit_code, 2);
  EXPECT_EQ(Render(1, {"--feed-fraction", "nan"}).exit_code, 2);
  EXPECT_EQ(Render(1, {"--spp", "0"}).exit_code, 2);
  EXPECT_EQ(Render(1, {"--pass-spp", "0", "-q"}).exit_code, 0);  // the default, written out
  EXPECT_EQ(Render(1, {"--convergence-log", dir_->File("no/such/dir/log.csv"), "-q"}).exit_code, 1);
  const ProcessResult help = RunProcess({kRaystack, "render", "--help"}, dir_->path());
  for (const char* option : {"--spp", "--pass-spp", "--pixel-order", "--time-limit",
                             "--target-error", "--convergence-log", "--reference"})
    EXPECT_NE(help.out.find(option), std::string::npos) << option;
}

}  // namespace
}  // namespace raystack::testing
