// A scene of many cameras as an animator renders it (found by one trying a turntable): part of
// a sequence re-rendered with --frames keeps its frames' numbers and images, one process or
// mpirun; --resume leaves complete frames' files untouched; a disk with room for a frame but
// perhaps not for the whole sequence at its largest is a warning, not a refusal.

#include <gtest/gtest.h>

#include <sys/mount.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/base/log.h"
#include "common/image/exr_io.h"
#include "tests/master/render_runs.h"
#include "tests/preview/background_process.h"
#include "tests/prep/run_process.h"
#include "tests/support/small_tmpfs.h"
#include "tests/support/store_dir_fixture.h"
#include "tests/support/test_dir.h"

namespace raystack::testing {
namespace {

using prep::testing::ProcessResult;
using prep::testing::RunProcess;
using prep::testing::Slurp;

class Sequence : public StoreDirFixture {
 protected:
  void SetUp() override {
    MakeStore("spheres:20000");
    std::string cameras;
    for (int i = 0; i < 4; ++i)
      cameras += StrFormat("%s{ \"position\": [%d, 5, 10], \"look_at\": [0, 0.5, 0], \"width\": 40, "
                           "\"height\": 30 }", i ? ", " : "", i);
    std::ofstream(dir_->File("turn.json")) << R"({ "store": "store", "cameras": [ )" << cameras
        << R"( ], "lights": [ { "type": "point", "position": [3, 8, 4], "intensity": [100, 100, 100] } ],
      "integrator": { "type": "path", "max_depth": 3, "spp": 4, "seed": 2 } })";
  }
  ProcessResult Render(const std::string& out, int np, std::vector<std::string> extra = {}) {
    std::vector<std::string> args = {dir_->File("turn.json"), "--threads", "1", "--output", out};
    args.insert(args.end(), extra.begin(), extra.end());
    return RunRender(dir_->path(), np, args);
  }
};

TEST_F(Sequence, FramesRendersPartOfTheSequenceUnderItsOwnNumbers) {
  const ProcessResult full = Render(dir_->File("full.exr"), 0, {"--no-png"});
  ASSERT_EQ(full.exit_code, 0) << full.err;
  for (int np : {0, 3}) {
    SCOPED_TRACE(np);
    const std::string out = dir_->File("part" + std::to_string(np) + ".exr");
    const ProcessResult part = Render(out, np, {"--frames", "1-2"});
    ASSERT_EQ(part.exit_code, 0) << part.err;
    // The job's progress, after each frame (the first with the time the rest should take).
    EXPECT_NE(part.out.find("sequence: 1 of 2 frames in "), std::string::npos) << part.out;
    EXPECT_NE(part.out.find(" left\n"), std::string::npos) << part.out;
    EXPECT_NE(part.out.find("sequence: 2 of 2 frames in "), std::string::npos) << part.out;
    const std::string stem = dir_->File("part" + std::to_string(np));
    for (int f : {0, 3}) EXPECT_FALSE(std::filesystem::exists(StrFormat("%s-%d.exr", stem.c_str(), f)));
    for (int f : {1, 2}) {
      EXPECT_TRUE(Slurp(StrFormat("%s-%d.exr", stem.c_str(), f)) ==
                  Slurp(dir_->File(StrFormat("full-%d.exr", f))))
          << "frame " << f << " is the full sequence's";
      EXPECT_TRUE(std::filesystem::exists(StrFormat("%s-%d.png", stem.c_str(), f)));
    }
  }
  // To the end, and one frame.
  ASSERT_EQ(Render(dir_->File("tail.exr"), 0, {"--frames", "3-", "--no-png"}).exit_code, 0);
  EXPECT_TRUE(Slurp(dir_->File("tail-3.exr")) == Slurp(dir_->File("full-3.exr")));
  EXPECT_FALSE(std::filesystem::exists(dir_->File("tail-2.exr")));
  ASSERT_EQ(Render(dir_->File("one.exr"), 0, {"--frames", "0", "--no-png"}).exit_code, 0);
  EXPECT_TRUE(Slurp(dir_->File("one-0.exr")) == Slurp(dir_->File("full-0.exr")));
}

TEST_F(Sequence, FramesOutsideTheSceneAreRefusedNamingItsCameras) {
  for (const auto& [range, code, said] : std::vector<std::tuple<std::string, int, std::string>>{
           {"4", 1, "--frames: the scene has 4 cameras (frames 0 to 3), no frame 4"},
           {"2-9", 1, "--frames: the scene has 4 cameras (frames 0 to 3), no frame 9"},
           {"2-1", 2, "--frames 2-1: the last frame comes before the first"},
           {"a-b", 2, "--frames a-b: give A, A-B or A-"},
           {"-3", 2, "--frames -3: give A, A-B or A-"}}) {
    const ProcessResult r = Render(dir_->File("x.exr"), 0, {"--frames", range});
    EXPECT_EQ(r.exit_code, code) << range << ": " << r.err;
    EXPECT_NE(r.err.find(said), std::string::npos) << range << ": " << r.err;
    EXPECT_FALSE(std::filesystem::exists(dir_->File("x-0.exr")));
  }
}

// --resume on a finished sequence renders nothing and leaves every file as it was: rewriting
// them gave each a new time, and a compositor reloaded the whole sequence.
TEST_F(Sequence, ResumeLeavesCompleteFramesUntouched) {
  const std::string out = dir_->File("seq.exr");
  ASSERT_EQ(Render(out, 0).exit_code, 0);
  const std::filesystem::path first = dir_->File("seq-0.exr");
  const auto before = std::filesystem::last_write_time(first);
  const std::string bytes = Slurp(first);
  std::filesystem::last_write_time(first, before - std::chrono::hours(1));  // an older render
  const auto older = std::filesystem::last_write_time(first);
  const ProcessResult again = Render(out, 0, {"--resume"});
  ASSERT_EQ(again.exit_code, 0) << again.err;
  EXPECT_NE(again.out.find("  kept " + first.string() + " (complete)"), std::string::npos)
      << again.out;
  EXPECT_EQ(std::filesystem::last_write_time(first), older);
  EXPECT_TRUE(Slurp(first) == bytes);
  // The time left goes by the frames rendered: the kept ones took none (found by an operator:
  // "2 of 6 frames in 0 s, about 0 s left" with most of the job to come).
  std::filesystem::remove(dir_->File("seq-2.exr"));
  std::filesystem::remove(dir_->File("seq-3.exr"));
  const ProcessResult half = Render(out, 0, {"--resume", "--stats", dir_->File("half.json")});
  ASSERT_EQ(half.exit_code, 0) << half.err;
  // Its statistics tell the frames kept from those rendered (found by the same operator).
  const nlohmann::json stats = nlohmann::json::parse(Slurp(dir_->File("half.json")));
  ASSERT_EQ(stats.size(), 4u);
  for (int f = 0; f < 4; ++f)
    EXPECT_EQ(stats[f]["kept_samples"], f < 2 ? 40 * 30 * 4 : 0) << f;
  // A kept frame after a rendered one whose image is still being written: the records stay in
  // frame order (a review: the kept frame's went in first).
  std::filesystem::remove(dir_->File("seq-1.exr"));
  const ProcessResult gap = Render(out, 0, {"--resume", "--stats", dir_->File("gap.json"),
                                            "--fault-slow-writes", "1"});
  ASSERT_EQ(gap.exit_code, 0) << gap.err;
  const nlohmann::json order = nlohmann::json::parse(Slurp(dir_->File("gap.json")));
  ASSERT_EQ(order.size(), 4u);
  for (int f = 0; f < 4; ++f) EXPECT_EQ(order[f]["frame"], f) << order;
  EXPECT_NE(half.out.find("sequence: 2 of 4 frames in 0 s\n"), std::string::npos) << half.out;
  const size_t third = half.out.find("sequence: 3 of 4 frames in ");
  ASSERT_NE(third, std::string::npos) << half.out;
  EXPECT_NE(half.out.substr(third, half.out.find('\n', third) - third).find(" left"),
            std::string::npos) << half.out;
}

// Found by the scale review: --stats was written once, at the end, from figures kept in memory
// for every frame; a run that failed (or was killed) on its 3rd frame left no figures at all.
// Each frame's record is written as it ends, the file a whole JSON array each time.
TEST_F(Sequence, StatsKeepTheFinishedFramesOfARunThatFails) {
  // A cache of a few blocks, so that every frame reads some; one thread that reads each block
  // as it misses it (--mode sync), so that two runs make the same reads.
  const std::vector<std::string> small = {"--cache-mb", "0.2", "--mode", "sync", "--no-png", "-q"};
  std::vector<std::string> extra = small;
  extra.insert(extra.end(), {"--stats", dir_->File("whole.json")});
  const ProcessResult whole = Render(dir_->File("whole.exr"), 0, extra);
  ASSERT_EQ(whole.exit_code, 0) << whole.err;
  const nlohmann::json all = nlohmann::json::parse(Slurp(dir_->File("whole.json")));
  ASSERT_EQ(all.size(), 4u);
  std::vector<uint64_t> loads;
  for (const nlohmann::json& frame : all) loads.push_back(frame["reads"].get<uint64_t>());
  ASSERT_GE(loads[2], 4u) << "every frame must read blocks";  // --fault-fail-read counts reads
  // The injected read error comes halfway through frame 2's reads.
  extra = small;
  extra.insert(extra.end(), {"--stats", dir_->File("failed.json"), "--fault-fail-read",
                             std::to_string(loads[0] + loads[1] + loads[2] / 2)});
  const ProcessResult failed = Render(dir_->File("failed.exr"), 0, extra);
  EXPECT_EQ(failed.exit_code, 1) << failed.err;
  EXPECT_NE(failed.err.find("read failed (injected fault)"), std::string::npos) << failed.err;
  nlohmann::json kept;
  ASSERT_NO_THROW(kept = nlohmann::json::parse(Slurp(dir_->File("failed.json"))));
  ASSERT_EQ(kept.size(), 2u) << kept;
  for (size_t f = 0; f < 2; ++f) {
    EXPECT_EQ(kept[f]["frame"], f);
    EXPECT_EQ(kept[f]["samples"], all[f]["samples"]);
  }
}

// The day's review: a checkpoint with every pixel finished (an interrupt at the frame's very
// end) was skipped by --resume as if complete: left "partial" for good, and no PNG; a complete
// frame whose PNG is missing got none either (now the PNG alone: the EXR keeps its time).
TEST_F(Sequence, ResumeFinishesACheckpointWithEveryPixelAndMakesAMissingPng) {
  const std::string out = dir_->File("cp.exr");
  ASSERT_EQ(Render(out, 0, {"--frames", "0-1"}).exit_code, 0);
  Expected<image::ImageLayers> frame = image::ReadExr(dir_->File("cp-0.exr"));
  ASSERT_TRUE(frame.ok()) << frame.status().message();
  frame->partial = true;  // the same pixels, written as a checkpoint
  ASSERT_TRUE(image::WriteExr(dir_->File("cp-0.exr"), *frame).ok());
  ASSERT_TRUE(image::IsPartialFrame(dir_->File("cp-0.exr")));
  std::filesystem::remove(dir_->File("cp-0.png"));
  std::filesystem::remove(dir_->File("cp-1.png"));
  const std::filesystem::path complete = dir_->File("cp-1.exr");
  const std::string bytes = Slurp(complete);
  std::filesystem::last_write_time(complete, std::filesystem::last_write_time(complete) -
                                                 std::chrono::hours(1));
  const auto older = std::filesystem::last_write_time(complete);
  const ProcessResult again = Render(out, 0, {"--frames", "0-1", "--resume"});
  ASSERT_EQ(again.exit_code, 0) << again.err;
  EXPECT_FALSE(image::IsPartialFrame(dir_->File("cp-0.exr")));
  for (const char* png : {"cp-0.png", "cp-1.png"})
    EXPECT_TRUE(std::filesystem::exists(dir_->File(png))) << png;
  EXPECT_EQ(std::filesystem::last_write_time(complete), older) << "the complete EXR is left";
  EXPECT_TRUE(Slurp(complete) == bytes);
}

// The day's review: the output's lock covered the whole sequence, so two jobs rendering other
// frames of one sequence (split between machines) were refused. Each job locks its frames; the
// lock is frame 0's file's, however the output is spelled; --stats has a lock of its own.
TEST_F(Sequence, JobsOnOtherFramesOfOneSequenceRunSideBySide) {
  const std::string out = dir_->File("split.exr");
  const std::string log = dir_->File("split.csv");
  master::preview::testing::BackgroundProcess first(
      {kRaystackBinary, "render", dir_->File("turn.json"), "--threads", "1", "--output", out,
       "--frames", "0-1", "--fault-slow-writes", "3", "--convergence-log", log, "--stats",
       dir_->File("split.json")},
      dir_->path());
  // Frame 0 ended (its row "0,end,") and its image is being written, slowly: the job holds its
  // frames for a while.
  for (int i = 0; i < 3000 && Slurp(log).find("0,end,") == std::string::npos && !first.Exited(); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_NE(Slurp(log).find("0,end,"), std::string::npos) << first.err();
  const ProcessResult other = Render(out, 0, {"--frames", "2-3"});
  EXPECT_EQ(other.exit_code, 0) << other.err;
  const ProcessResult overlapping = Render(out, 0, {"--frames", "1-2"});
  EXPECT_EQ(overlapping.exit_code, 1);
  EXPECT_NE(overlapping.err.find("another raystack render is writing this output now"),
            std::string::npos) << overlapping.err;
  // The same files spelled otherwise (found by an operator: each spelling took a lock of its
  // own, and both jobs wrote the files): "split-#.exr" names split-0.exr ... as "split.exr" does.
  const ProcessResult spelled = Render(dir_->File("split-#.exr"), 0, {"--frames", "1"});
  EXPECT_EQ(spelled.exit_code, 1) << spelled.err;
  EXPECT_NE(spelled.err.find("another raystack render is writing this output now"),
            std::string::npos) << spelled.err;
  // Other frames, another output, but the first job's --stats (found by the same operator: the
  // two jobs' records in one file made it unreadable).
  const ProcessResult stats = Render(dir_->File("other.exr"), 0, {"--stats", dir_->File("split.json")});
  EXPECT_EQ(stats.exit_code, 1) << stats.err;
  EXPECT_NE(stats.err.find("split.json: another raystack render is writing this output now"),
            std::string::npos) << stats.err;
  EXPECT_NE(stats.err.find("give another --stats"), std::string::npos) << stats.err;
  // Its convergence log too (a pipeline review: two jobs' rows in one log, which
  // raystack-plot then refused).
  for (int np : {0, 3}) {
    SCOPED_TRACE(np);
    const ProcessResult logged = Render(dir_->File("other3.exr"), np, {"--convergence-log", log});
    EXPECT_NE(logged.exit_code, 0) << logged.err;
    EXPECT_NE(logged.err.find("split.csv: cannot write the convergence log: another raystack "
                              "render is writing this log now"),
              std::string::npos) << logged.err;
    EXPECT_NE(logged.err.find("give another --convergence-log"), std::string::npos) << logged.err;
    EXPECT_NE(Slurp(log).find("0,end,"), std::string::npos) << "the first job's log was emptied";
  }
  // Through a link to it (a review: the lock went by the link's name, the file written by its
  // target's, and one job's records were lost).
  std::filesystem::create_symlink(dir_->File("split.json"), dir_->File("link.json"));
  const ProcessResult linked = Render(dir_->File("other2.exr"), 0, {"--stats", dir_->File("link.json")});
  EXPECT_EQ(linked.exit_code, 1) << linked.err;
  EXPECT_NE(linked.err.find("split.json: another raystack render is writing this output now"),
            std::string::npos) << linked.err;
  EXPECT_EQ(first.Wait(), 0) << first.err();
  for (int f = 0; f < 4; ++f)
    EXPECT_TRUE(std::filesystem::exists(dir_->File(StrFormat("split-%d.exr", f)))) << f;
  EXPECT_FALSE(std::filesystem::exists(dir_->File(".split-0.exr.lock"))) << "the last one removes it";
  EXPECT_TRUE(std::filesystem::exists(dir_->File("split.json")));
}

// --stats on the standard output, as scripts use it (a review): with the output sent to a file
// (the harness does), the records go into that file beside the run's text, not over it; a reader
// that goes away (`| head`) is a failed write, said, and the render goes on to its last frame
// (its signal ended the job mid-sequence, the output's lock left);
// --stats naming one of the job's own images is refused before rendering.
TEST_F(Sequence, StatsOnTheStandardOutputAndNotOverAnImage) {
  ProcessResult r = Render(dir_->File("std.exr"), 0, {"--stats", "/dev/stdout", "-q", "--no-png"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  nlohmann::json records;
  ASSERT_NO_THROW(records = nlohmann::json::parse(r.out)) << r.out;
  ASSERT_EQ(records.size(), 4u);
  EXPECT_EQ(records[3]["frame"], 3);
  r = Render(dir_->File("std.exr"), 0, {"--stats", "/dev/stdout", "--no-png"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("sequence: 4 of 4 frames"), std::string::npos) << r.out;  // the text stays
  EXPECT_NE(r.out.find("\"frame\": 3"), std::string::npos) << r.out;

  const std::string command = std::string(kRaystackBinary) + " render " + dir_->File("turn.json") +
                              " --threads 1 --output " + dir_->File("cut.exr") + " --no-png -q " +
                              "--stats /dev/stdout | head -c 10 > /dev/null; echo \"render exit ${PIPESTATUS[0]}\"";
  r = RunProcess({"/bin/bash", "-c", command}, dir_->path());
  // (1: the statistics asked for were not all written; the message says why.)
  EXPECT_NE(r.out.find("render exit 1"), std::string::npos) << r.out << r.err;
  EXPECT_NE(r.err.find("/dev/stdout: cannot write the statistics: Broken pipe"), std::string::npos) << r.err;
  for (int f = 0; f < 4; ++f)
    EXPECT_TRUE(std::filesystem::exists(dir_->File(StrFormat("cut-%d.exr", f)))) << f << r.err;

  r = Render(dir_->File("img.exr"), 0, {"--frames", "2-3", "--stats", dir_->File("img-0.exr")});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("img-0.exr, an image of this job's output"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir_->File("img-2.exr")));
}

// Found by an operator: a store converted again while a sequence rendered. The job rendered the
// store it had opened (its files stay open), but the images of the later frames recorded the new
// store, and --resume then finished a frame of the old model with the new one. The images record
// the store as the job found it, and the job says the store was replaced.
TEST_F(Sequence, AStoreReplacedMidJobIsSaidAndTheImagesRecordTheOneRendered) {
  for (int np : {0, 3}) {
    SCOPED_TRACE(np);
    const std::string tag = std::to_string(np);
    ASSERT_EQ(prep::testing::RunProcess({prep::testing::kPrepBinary, "--generate", "spheres:20000",
                                         "-o", dir_->File("store"), "--target-block-kb", "8", "-q"},
                                        dir_->path()).exit_code, 0);
    const std::string log = dir_->File("replaced" + tag + ".csv");
    std::vector<std::string> argv;
    if (np > 0)
      argv = {RAYSTACK_MPIRUN, "--allow-run-as-root", "--oversubscribe", "-np", std::to_string(np)};
    for (const std::string& a : {kRaystackBinary, std::string("render"), dir_->File("turn.json"),
                                 std::string("--threads"), std::string("1"), std::string("--output"),
                                 dir_->File("replaced" + tag + ".exr"), std::string("--no-png"),
                                 std::string("--fault-slow-writes"), std::string("1"),
                                 std::string("--convergence-log"), log})
      argv.push_back(a);
    master::preview::testing::BackgroundProcess job(argv, dir_->path());
    // Frame 0 ended: its image is written slowly, and frame 3 starts once frames 1 and 2 have
    // been taken by the writer (seconds from now): the store is converted again meanwhile.
    for (int i = 0; i < 3000 && Slurp(log).find("0,end,") == std::string::npos && !job.Exited(); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    ASSERT_NE(Slurp(log).find("0,end,"), std::string::npos) << job.err();
    ASSERT_EQ(prep::testing::RunProcess({prep::testing::kPrepBinary, "--generate", "sphere:3000",
                                         "-o", dir_->File("store"), "-q"}, dir_->path()).exit_code, 0);
    ASSERT_EQ(job.Wait(), 0) << job.err();
    EXPECT_NE(job.err().find("the store was replaced (converted again?) after this job opened it"),
              std::string::npos) << job.err();
    auto store_line = [&](int f) {
      Expected<image::ImageLayers> frame = image::ReadExr(dir_->File(StrFormat("replaced%s-%d.exr", tag.c_str(), f)));
      EXPECT_TRUE(frame.ok());
      if (!frame.ok()) return std::string();
      const size_t at = frame->provenance.find("\nstore ");
      return frame->provenance.substr(at, frame->provenance.find('\n', at + 1) - at);
    };
    EXPECT_FALSE(store_line(0).empty());
    EXPECT_EQ(store_line(3), store_line(0));
  }
}

// Found by an animator: the noise depends on (seed, pixel, sample) only, so it stayed on the
// screen as the camera moved, with no way to change that. "animated_seed" gives each frame its
// own: two frames of one camera differ, and stay the same from one process to mpirun.
TEST_F(Sequence, AnimatedSeedGivesEachFrameItsOwnNoise) {
  const std::string same = R"({ "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 40, "height": 30 })";
  for (const bool animated : {false, true}) {
    SCOPED_TRACE(animated);
    std::ofstream(dir_->File("still.json"))
        << R"({ "store": "store", "cameras": [ )" << same << ", " << same << R"( ],
      "lights": [ { "type": "point", "position": [3, 8, 4], "intensity": [100, 100, 100] } ],
      "integrator": { "type": "path", "max_depth": 3, "spp": 2, "seed": 2, "animated_seed": )"
        << (animated ? "true" : "false") << " } }";
    std::vector<std::string> frames[2];
    for (int np : {0, 3}) {
      const std::string out = dir_->File(StrFormat("still%d%d.exr", animated, np));
      const ProcessResult r = RunRender(dir_->path(), np, {dir_->File("still.json"), "--threads",
                                                           "1", "--no-png", "--output", out});
      ASSERT_EQ(r.exit_code, 0) << r.err;
      for (int f : {0, 1}) {
        Expected<image::ImageLayers> image =
            image::ReadExr(dir_->File(StrFormat("still%d%d-%d.exr", animated, np, f)));
        ASSERT_TRUE(image.ok()) << image.status().message();
        frames[np > 0].push_back(std::string(reinterpret_cast<const char*>(image->rgba.data()),
                                             image->rgba.size() * sizeof(float)));
      }
    }
    EXPECT_EQ(frames[0][0] == frames[0][1], !animated) << "the two frames' pixels";
    EXPECT_TRUE(frames[0] == frames[1]) << "mpirun renders what one process does";
  }
}

// Found by an animator: one 640x360 camera among 320x240 ones went unnoticed until a video tool
// quietly squashed it.
TEST_F(Sequence, CamerasOfDifferentSizesAreAWarning) {
  std::ofstream(dir_->File("mixed.json")) << R"({ "store": "store", "cameras": [
    { "position": [0, 5, 10], "width": 32, "height": 24 },
    { "position": [1, 5, 10], "width": 32, "height": 24 },
    { "position": [2, 5, 10], "width": 64, "height": 36 } ] })";
  for (int np : {0, 3}) {
    const ProcessResult r =
        RunRender(dir_->path(), np, {dir_->File("mixed.json"), "--output", dir_->File("mixed.exr")});
    EXPECT_EQ(r.exit_code, 0) << r.err;
    EXPECT_NE(r.err.find("camera 2 is 64x36 where camera 0 is 32x24: an image sequence usually "
                         "keeps one size"), std::string::npos) << np << ": " << r.err;
  }
}

// Found by an animator: a camera inside the model (the light outside) gave an all-black frame,
// and one looking away from it an empty one, without a word.
TEST(SequenceWarnings, AFrameThatShowsNothingIsAWarning) {
  std::unique_ptr<TempDir> dir = MakeTestDir();
  ASSERT_TRUE(dir);
  ASSERT_EQ(RunProcess({prep::testing::kPrepBinary, "--generate", "sphere:2000", "-o",
                        dir->File("store"), "-q"}, dir->path()).exit_code, 0);
  std::ofstream(dir->File("scene.json")) << R"({ "store": "store", "cameras": [
    { "position": [0, 0, 4], "look_at": [0, 0, 0], "width": 24, "height": 16 },
    { "position": [0, 0, 0.2], "look_at": [0, 0, 1], "width": 24, "height": 16 },
    { "position": [0, 0, 4], "look_at": [0, 0, 8], "width": 24, "height": 16 } ],
    "lights": [ { "type": "point", "position": [3, 8, 4], "intensity": [100, 100, 100] } ] })";
  const ProcessResult r = RunProcess({kRaystackBinary, "render", dir->File("scene.json"), "--output",
                                      dir->File("f.exr"), "--no-png"}, dir->path());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find("frame 0:"), std::string::npos) << "frame 0 sees the lit sphere: " << r.err;
  EXPECT_EQ(r.err.find("frame 0 is"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("frame 1 is black: every pixel 0 (is the camera inside the model"),
            std::string::npos) << r.err;
  EXPECT_NE(r.err.find("frame 2: no camera ray met the model"), std::string::npos) << r.err;
  // Found by a rendering researcher: a lamp of 1e-15 gave a black image (the film's fixed-point
  // step is 2^-50), one of 1e-10 errors of 3%, without a word.
  for (const auto& [intensity, said] : std::vector<std::pair<std::string, std::string>>{
           {"1e-9", "frame 0 is very dim (its brightest pixel "},
           {"1e-17", "frame 0 is black: every pixel 0"}}) {
    std::ofstream(dir->File("dim.json")) << R"({ "store": "store",
      "camera": { "position": [0, 0, 4], "look_at": [0, 0, 0], "width": 24, "height": 16 },
      "lights": [ { "type": "point", "position": [3, 8, 4], "intensity": [)" << intensity << ", "
        << intensity << ", " << intensity << "] } ] }";
    const ProcessResult dim = RunProcess({kRaystackBinary, "render", dir->File("dim.json"),
                                          "--output", dir->File("dim.exr"), "--no-png"}, dir->path());
    ASSERT_EQ(dim.exit_code, 0) << dim.err;
    EXPECT_NE(dim.err.find(said), std::string::npos) << intensity << ": " << dim.err;
    EXPECT_NE(dim.err.find("scale the lights (and emission, background) up"), std::string::npos)
        << dim.err;
  }
}

// 10 cameras of 40 x 30 take up to 672 KB uncompressed; a 256 KB disk holds one frame (and in
// fact all of them, compressed): a warning, and the render goes on (it was refused).
TEST(SequenceRoom, ADiskWithRoomForAFrameIsAWarningNotARefusal) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  const SmallTmpfs tmpfs(dir->File("small"), "size=256k");
  if (tmpfs.path.empty()) GTEST_SKIP() << tmpfs.why;
  const std::string& small = tmpfs.path;
  std::string cameras;
  for (int i = 0; i < 10; ++i)
    cameras += StrFormat("%s{ \"position\": [%d, 5, 10], \"look_at\": [0, 0, 0], \"width\": 40, "
                         "\"height\": 30 }", i ? ", " : "", i);
  std::ofstream(dir->File("scene.json")) << R"({ "store": "no-such-store", "cameras": [ )"
                                         << cameras << " ] }";
  const ProcessResult r = RunProcess(
      {kRaystackBinary, "render", dir->File("scene.json"), "--output", small + "/f.exr"},
      dir->path());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find(small + "/f-0.exr: the disk holding it has 0.3 MB free; the 10 frames' "
                       "images take up to 0.7 MB uncompressed (usually far less)"),
            std::string::npos) << r.err;
  EXPECT_NE(r.err.find("no-such-store"), std::string::npos) << "went on to the store: " << r.err;
}

}  // namespace
}  // namespace raystack::testing
