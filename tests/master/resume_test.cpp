// --resume continues from the checkpoint a killed run left: the image equals an uninterrupted
// run's byte for byte, in one process and under mpirun. The "killed run" is made exactly: the
// finished image with some tiles' pixels taken back to partly or not rendered (fewer samples,
// wrong values), as a checkpoint written mid-render holds them.

#include <gtest/gtest.h>

#include <cmath>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "common/base/log.h"
#include "common/image/exr_io.h"
#include "common/render/frame_plan.h"
#include "master/resume.h"
#include "tests/preview/background_process.h"
#include "tests/prep/run_process.h"
#include "tests/master/render_runs.h"
#include "tests/support/store_dir_fixture.h"

namespace raystack::testing {
namespace {

using prep::testing::ProcessResult;
using prep::testing::RunProcess;
using prep::testing::Slurp;

class Resume : public StoreDirFixture {
 protected:
  void SetUp() override {
    MakeStore("spheres:20000");
    std::ofstream(dir_->File("scene.json")) << R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 96, "height": 64 },
      "lights": [ { "type": "point", "position": [3, 8, 4], "intensity": [100, 100, 100] } ],
      "materials": { "default": { "type": "diffuse", "albedo": [0.7, 0.6, 0.5] } },
      "integrator": { "type": "path", "max_depth": 3, "spp": 3, "seed": 4 } })";
  }
  ProcessResult Render(const std::string& out, int np, std::vector<std::string> extra = {}) {
    std::vector<std::string> args = {dir_->File("scene.json"), "--threads", "2", "--cache-mb", "1",
                                     "--tile-size", "16", "--output", out, "--no-png"};
    args.insert(args.end(), extra.begin(), extra.end());
    return RunRender(dir_->path(), np, args);
  }
  // Flags of a render in whole tiles (one pass) with a checkpoint every 0.05 s: 48 samples per
  // pixel, so it outlasts a few checkpoints, and a mid-render checkpoint holds finished pixels.
  static std::vector<std::string> WholeTiles() {
    return {"--spp", "48", "--pass-spp", "48", "--checkpoint-s", "0.05"};
  }
  // The EXR bytes of an uninterrupted whole-tile render.
  std::string Uninterrupted() {
    const ProcessResult full = Render(dir_->File("full.exr"), 0, WholeTiles());
    EXPECT_EQ(full.exit_code, 0) << full.err;
    return Slurp(dir_->File("full.exr"));
  }
};

TEST_F(Resume, TheResumedImageEqualsAnUninterruptedRun) {
  const ProcessResult full = Render(dir_->File("full.exr"), 0);
  ASSERT_EQ(full.exit_code, 0) << full.err;
  Expected<image::ImageLayers> image = image::ReadExr(dir_->File("full.exr"));
  ASSERT_TRUE(image.ok()) << image.status().message();
  // The checkpoint: the left half of the image finished, in the right half some pixels with 1
  // of 3 samples and absurd values, the rest never reached.
  image::ImageLayers partial = *image;
  for (int y = 0; y < partial.height; ++y)
    for (int x = partial.width / 2; x < partial.width; ++x) {
      const size_t i = partial.PixelIndex(x, y);
      const bool reached = (x + y) % 3 == 0;
      partial.samples[i] = reached ? 1 : 0;
      for (int c = 0; c < 4; ++c) partial.rgba[4 * i + c] = reached ? 1e4f : 0.0f;
      partial.variance[i] = 0;
    }
  const std::string expected = Slurp(dir_->File("full.exr"));
  for (int np : {0, 3}) {
    const std::string out = dir_->File("resumed" + std::to_string(np) + ".exr");
    ASSERT_TRUE(image::WriteExr(out, partial).ok());
    const std::string log = dir_->File("resumed" + std::to_string(np) + ".csv");
    const ProcessResult r = Render(out, np, {"--resume", "--convergence-log", log});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    // 96x64: the left half (3072 pixels) kept.
    EXPECT_NE(r.out.find("3072 of 6144 pixels finished"), std::string::npos) << r.out;
    EXPECT_TRUE(Slurp(out) == expected) << "np " << np;
    // The passes (3 samples per pixel: 1, 1, 1) still end, though the restored pixels are not
    // rendered again: the log has a row for each (and --target-error could stop at one).
    const std::string rows = Slurp(log);
    for (int pass = 1; pass <= 3; ++pass)
      EXPECT_NE(rows.find(StrFormat("0,pass,%d,", pass)), std::string::npos)
          << "np " << np << ": no end of pass " << pass << " in\n" << rows;
  }
}

// The whole job really dies (SIGKILL right after a checkpoint; under mpirun the others go
// with it), and --resume finishes from that checkpoint.
TEST_F(Resume, AJobKilledAfterACheckpointResumesToTheSameImage) {
  const std::string expected = Uninterrupted();
  ASSERT_FALSE(expected.empty());
  for (int np : {0, 3}) {
    const std::string out = dir_->File("killed" + std::to_string(np) + ".exr");
    // Checkpoints come by the clock, tiles as fast as the machine renders them, and the
    // checkpoint writer runs at nice 19: on a loaded machine (a full ctest -j2) the 2nd
    // checkpoint can come before the first tile is finished ("no finished pixel"), or the
    // starved writer finishes too few checkpoints before the render ends (not killed). Each
    // such attempt says nothing about resuming, so the kill moves later or sooner until a
    // checkpoint holds finished pixels; what every attempt did is printed if none does.
    uint64_t finished = 0;
    image::ImageLayers checkpoint;
    std::string attempts;
    int kill_after = 2;
    for (int attempt = 0; attempt < 12 && finished == 0; ++attempt) {
      std::vector<std::string> killed = WholeTiles();
      killed.insert(killed.end(), {"--fault-kill-after-checkpoints", std::to_string(kill_after)});
      std::filesystem::remove(out);  // the last attempt's checkpoint: a run without --resume refuses it
      const ProcessResult died = Render(out, np, killed);
      attempts += StrFormat(" [kill after %d: exit %d", kill_after, died.exit_code);
      if (died.exit_code == 0) {  // the render outran its checkpoints: kill it sooner
        attempts += ", not killed]";
        kill_after = std::max(1, kill_after / 2);
        continue;
      }
      Expected<image::ImageLayers> read = image::ReadExr(out);
      ASSERT_TRUE(read.ok()) << read.status().message();
      checkpoint = *read;
      for (uint32_t n : checkpoint.samples) finished += n == 48;
      attempts += StrFormat(", %llu finished]", static_cast<unsigned long long>(finished));
      kill_after = std::min(32, kill_after * 2);
    }
    ASSERT_GT(finished, 0u) << "np " << np << ": no checkpoint held a finished pixel:" << attempts;
    EXPECT_LT(finished, checkpoint.samples.size()) << "np " << np << ": the checkpoint is whole";
    const ProcessResult resumed = Render(out, np, {"--spp", "48", "--pass-spp", "48", "--resume"});
    ASSERT_EQ(resumed.exit_code, 0) << resumed.err;
    EXPECT_NE(resumed.out.find(std::to_string(finished) + " of 6144 pixels finished"),
              std::string::npos) << resumed.out;
    EXPECT_TRUE(Slurp(out) == expected) << "np " << np;
  }
}

// Found by a render-farm operator: a run without --resume overwrote the unfinished frame a
// killed run left, its finished pixels lost without a word. The EXR now says whether it is a
// frame's final image ("raystack.state": complete) or not (partial: a checkpoint), and a run
// without --resume refuses a partial one, naming the way out; a final image is replaced as ever.
TEST_F(Resume, AnUnfinishedFrameIsNotOverwrittenWithoutResume) {
  const std::string out = dir_->File("frame.exr");
  // Long enough (480 samples a pixel) to be killed by its first checkpoint on a loaded machine,
  // in whole tiles of 4 x 4 that finish one by one, so that the checkpoint holds finished
  // pixels (one with none is not protected: nothing in it for --resume).
  const std::vector<std::string> slow = {"--spp", "480", "--pass-spp", "480", "--tile-size", "4"};
  std::vector<std::string> killed = slow;
  killed.insert(killed.end(), {"--checkpoint-s", "0.15", "--fault-kill-after-checkpoints", "1"});
  const ProcessResult died = Render(out, 0, killed);
  ASSERT_NE(died.exit_code, 0) << "the render outran its first checkpoint: " << died.err;
  Expected<image::ImageLayers> checkpoint = image::ReadExr(out);
  ASSERT_TRUE(checkpoint.ok()) << checkpoint.status().message();
  EXPECT_TRUE(checkpoint->partial);
  ASSERT_TRUE(std::any_of(checkpoint->samples.begin(), checkpoint->samples.end(),
                          [](uint32_t n) { return n >= 480; })) << "no tile finished by then";
  EXPECT_TRUE(image::IsPartialFrame(out));
  const std::string left = Slurp(out);

  const ProcessResult refused = Render(out, 0, slow);
  EXPECT_EQ(refused.exit_code, 1) << refused.err;
  EXPECT_NE(refused.err.find(out + " holds a frame a stopped run left unfinished: --resume "
                             "continues it"), std::string::npos) << refused.err;
  EXPECT_TRUE(Slurp(out) == left) << "the unfinished frame was touched";

  std::vector<std::string> resume = slow;
  resume.push_back("--resume");
  const ProcessResult resumed = Render(out, 0, resume);
  ASSERT_EQ(resumed.exit_code, 0) << resumed.err;
  Expected<image::ImageLayers> final_image = image::ReadExr(out);
  ASSERT_TRUE(final_image.ok());
  EXPECT_FALSE(final_image->partial);
  EXPECT_FALSE(image::IsPartialFrame(out));
  // A final image is replaced by a new run as before.
  EXPECT_EQ(Render(out, 0, slow).exit_code, 0);
}

// Ctrl-C (SIGINT), or SIGTERM to mpirun (Slurm at a job's time limit; mpirun passes it on to
// every rank and sends SIGKILL a second later): the master writes the frame so far where
// --resume finds it, says so, and ends with the signal's code; --resume then finishes the same
// image as an uninterrupted run. Before, the run left nothing (no --checkpoint-s here).
TEST_F(Resume, AnInterruptedRunLeavesItsFrameForResume) {
  const std::vector<std::string> flags = {"--spp", "300", "--pass-spp", "300"};  // whole tiles
  const ProcessResult full = Render(dir_->File("full.exr"), 0, flags);
  ASSERT_EQ(full.exit_code, 0) << full.err;
  const std::string expected = Slurp(dir_->File("full.exr"));
  ASSERT_FALSE(expected.empty());
  for (int np : {0, 3}) {
    SCOPED_TRACE(np);
    const std::string out = dir_->File("interrupted" + std::to_string(np) + ".exr");
    std::vector<std::string> argv;
    if (np > 0) argv = {RAYSTACK_MPIRUN, "--allow-run-as-root", "--oversubscribe", "-np", std::to_string(np)};
    for (const std::string& a : {kRaystackBinary, std::string("render"), dir_->File("scene.json"),
                                 std::string("--threads"), std::string("1"), std::string("--tile-size"),
                                 std::string("4"), std::string("--output"), out, std::string("--no-png")})
      argv.push_back(a);
    argv.insert(argv.end(), flags.begin(), flags.end());
    // A convergence-log row with samples says the frame renders (no --checkpoint-s: a
    // checkpoint being written at nice 19 on a loaded machine would hold the interrupt's
    // write back past mpirun's SIGKILL).
    const std::string log = dir_->File("interrupted" + std::to_string(np) + ".csv");
    argv.insert(argv.end(), {"--convergence-log", log, "--log-interval", "0.05"});
    master::preview::testing::BackgroundProcess run(argv, dir_->path());
    // 4 x 4 tiles of 300 samples a pixel take them in one sweep, so a tile's pixels finish with
    // it: an interrupt with none finished keeps nothing (and writes nothing). Interrupted once
    // the merged samples are those of 20 tiles, more than the tiles in flight at once.
    auto rendering = [&] {  // a row "0,tick,pass,seconds,rays,samples,..." with them
      std::istringstream rows(Slurp(log));
      for (std::string row; std::getline(rows, row);) {
        if (row.rfind("0,tick,", 0) != 0) continue;
        std::istringstream fields(row);
        std::string field;
        for (int i = 0; i < 6; ++i) std::getline(fields, field, ',');
        if (std::strtoull(field.c_str(), nullptr, 10) >= 20 * 16 * 300) return true;
      }
      return false;
    };
    for (int i = 0; i < 3000 && !rendering(); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    ASSERT_TRUE(rendering()) << run.out() << run.err();
    ASSERT_FALSE(std::filesystem::exists(out)) << "nothing is written before the interrupt";
    run.Signal(np > 0 ? SIGTERM : SIGINT);
    const int code = run.Wait();
    if (np == 0) EXPECT_EQ(code, 128 + SIGINT) << run.err();
    else EXPECT_NE(code, 0) << run.err();
    EXPECT_NE(run.err().find(np > 0 ? "interrupted (SIGTERM): the frame so far is in"
                                    : "interrupted (SIGINT): the frame so far is in"),
              std::string::npos) << run.err();
    Expected<image::ImageLayers> left = image::ReadExr(out);
    ASSERT_TRUE(left.ok()) << left.status().message();
    EXPECT_FALSE(left->provenance.empty());
    uint64_t samples = 0;
    for (const uint32_t n : left->samples) samples += n;
    EXPECT_GT(samples, 0u);
    EXPECT_LT(samples, 300u * 6144) << "the render finished before the signal";
    const ProcessResult resumed = Render(out, np, {"--spp", "300", "--pass-spp", "300", "--resume"});
    ASSERT_EQ(resumed.exit_code, 0) << resumed.err;
    EXPECT_TRUE(Slurp(out) == expected);
  }
}

// A three-frame job whose frames each stop after --time-limit, written behind the render by
// a writer that is slow (--fault-slow-writes) or fails (--fault-fail-writes), interrupted
// `after` seconds once frame `frame` renders (with PNG quick-looks when `png`), by `signal`
// sent `times` times in quick succession. Returns the run's exit code; `err` its stderr. `wrapper`: a
// command the job runs under.
int InterruptFrame(const TempDir& dir, int frame, double after, const std::string& fault,
                   const std::string& value, std::string* err, bool png = false,
                   int signal = SIGINT, const std::string& wrapper = "", int times = 1) {
  std::ofstream(dir.File("three.json")) << R"({ "store": "store",
    "cameras": [ { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 48, "height": 32 },
                 { "position": [1, 5, 10], "look_at": [0, 0.5, 0], "width": 48, "height": 32 },
                 { "position": [2, 5, 10], "look_at": [0, 0.5, 0], "width": 48, "height": 32 } ],
    "lights": [ { "type": "point", "position": [3, 8, 4], "intensity": [100, 100, 100] } ],
    "integrator": { "type": "path", "max_depth": 3, "spp": 60000, "seed": 4 } })";
  const std::string log = dir.File("three.csv");
  std::filesystem::remove(log);  // (an earlier call's rows would say "rendering" at once)
  std::vector<std::string> args;
  if (!wrapper.empty()) args.push_back(wrapper);
  args.insert(args.end(), {
      kRaystackBinary, "render", dir.File("three.json"), "--threads", "1", "--time-limit", "0.3",
      "--output", dir.File("frame.exr"), fault, value, "--convergence-log", log,
      "--log-interval", "0.05"});
  if (!png) args.push_back("--no-png");
  master::preview::testing::BackgroundProcess run(args, dir.path());
  // Progressive passes of 60000 samples: no pixel of a frame is finished when it is interrupted.
  const std::string row = StrFormat("\n%d,tick,", frame);
  auto rendering = [&] { return Slurp(log).find(row) != std::string::npos; };
  for (int i = 0; i < 3000 && !rendering() && !run.Exited(); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_TRUE(rendering()) << run.out() << run.err();
  std::this_thread::sleep_for(std::chrono::duration<double>(after));
  for (int i = 0; i < times; ++i) {
    // (20 ms apart: two sent at once merge into one pending signal before the job runs.)
    if (i > 0) std::this_thread::sleep_for(std::chrono::milliseconds(20));
    run.Signal(signal);
  }
  const int code = run.Wait();
  *err = run.err();
  return code;
}

// Found by an animator: Ctrl-C with no pixel of the frame rendering finished ended the process
// without the images of the frames that had finished, which the writer still held (it runs at
// low priority, and fell two frames behind on a busy machine): they are written first.
TEST_F(Resume, AnInterruptKeepsTheFramesThatFinishedBehindASlowDisk) {
  std::string err;
  EXPECT_EQ(InterruptFrame(*dir_, 1, 0, "--fault-slow-writes", "2", &err), 128 + SIGINT) << err;
  // The frame rendering is written to look at, though --resume can keep none of it (a new user's
  // Ctrl-C in the first passes had left no image of minutes of work).
  EXPECT_NE(err.find("interrupted (SIGINT): the frame so far is in " + dir_->File("frame-1.exr") +
                     " to look at, but no pixel has all its"),
            std::string::npos) << err;
  EXPECT_NE(err.find("so --resume keeps none of it"), std::string::npos) << err;
  Expected<image::ImageLayers> frame0 = image::ReadExr(dir_->File("frame-0.exr"));
  ASSERT_TRUE(frame0.ok()) << frame0.status().message() << "\n" << err;
  EXPECT_FALSE(frame0->partial);
  Expected<image::ImageLayers> frame1 = image::ReadExr(dir_->File("frame-1.exr"));
  ASSERT_TRUE(frame1.ok()) << frame1.status().message() << "\n" << err;
  EXPECT_TRUE(frame1->partial);
  // Nothing there for --resume to keep, so a plain run renders it from the start, not refused
  // as unfinished (the day's review).
  const ProcessResult again = RunProcess({kRaystackBinary, "render", dir_->File("three.json"),
                                          "--threads", "1", "--time-limit", "0.1", "--frames", "1",
                                          "--output", dir_->File("frame.exr"), "--no-png"},
                                         dir_->path());
  EXPECT_EQ(again.exit_code, 0) << again.err;
  EXPECT_NE(again.err.find("frame-1.exr: a stopped run's frame with no pixel finished"),
            std::string::npos) << again.err;
  EXPECT_FALSE(image::IsPartialFrame(dir_->File("frame-1.exr")));
}

// The frame written to look at has its PNG quick-look beside it, of the same pixels: an
// earlier run's finished PNG stayed there, beside the interrupted frame's EXR.
TEST_F(Resume, AnInterruptedFrameToLookAtHasItsPngToo) {
  std::ofstream(dir_->File("frame-1.png")) << "an earlier run's PNG";
  std::string err;
  EXPECT_EQ(InterruptFrame(*dir_, 1, 0, "--fault-slow-writes", "0", &err, /*png=*/true),
            128 + SIGINT) << err;
  EXPECT_NE(err.find("the frame so far is in " + dir_->File("frame-1.exr") + " (and " +
                     dir_->File("frame-1.png") + ") to look at"),
            std::string::npos) << err;
  EXPECT_TRUE(image::IsPartialFrame(dir_->File("frame-1.exr")));
  const std::string png = Slurp(dir_->File("frame-1.png"));
  ASSERT_GT(png.size(), 8u) << err;
  EXPECT_EQ(png.substr(1, 3), "PNG") << "the earlier run's PNG stayed";
}

// Found by a pipeline review: a closed terminal or ssh session (SIGHUP) ended the job with
// nothing written and no word. It is an interrupt as Ctrl-C is, said with its cause; under
// nohup (SIGHUP ignored) the job goes on.
TEST_F(Resume, AHangupIsAnInterruptUnlessIgnored) {
  std::string err;
  EXPECT_EQ(InterruptFrame(*dir_, 1, 0, "--fault-slow-writes", "0", &err, false, SIGHUP),
            128 + SIGHUP) << err;
  EXPECT_NE(err.find("interrupted (SIGHUP): the frame so far is in " + dir_->File("frame-1.exr")),
            std::string::npos) << err;
  EXPECT_NE(err.find("SIGHUP: the terminal or ssh session that started the job closed"),
            std::string::npos) << err;
  EXPECT_TRUE(image::IsPartialFrame(dir_->File("frame-1.exr")));
  EXPECT_EQ(InterruptFrame(*dir_, 1, 0, "--fault-slow-writes", "0", &err, false, SIGHUP, "/usr/bin/nohup"),
            0) << err;
  EXPECT_FALSE(image::IsPartialFrame(dir_->File("frame-2.exr"))) << err;
}

// GNU timeout sends SIGTERM to its child and then to its own process group: two at once, and
// the second ended the job at once, its frame half written (a soak test). The same signal again
// within a quarter of a second is the same sending.
TEST_F(Resume, TwoSignalsAtOnceAreOneInterrupt) {
  std::string err;
  EXPECT_EQ(InterruptFrame(*dir_, 1, 0, "--fault-slow-writes", "0.5", &err, false, SIGTERM, "", 2),
            128 + SIGTERM) << err;
  EXPECT_NE(err.find("interrupted (SIGTERM): the frame so far is in " + dir_->File("frame-1.exr")),
            std::string::npos) << err;
  EXPECT_TRUE(image::IsPartialFrame(dir_->File("frame-1.exr")));
  Expected<image::ImageLayers> frame0 = image::ReadExr(dir_->File("frame-0.exr"));
  ASSERT_TRUE(frame0.ok()) << frame0.status().message() << "\n" << err;
  EXPECT_FALSE(frame0->partial) << "frame 0, written behind a slow disk, was lost";
}

// Ctrl-C while a finished frame's write is tried again (a full disk) gives it up, and the job
// ends as interrupted (128 + SIGINT), naming the frames rendered and not written: interrupted
// as frame 1 renders, and once frame 2 has ended and waits for the writer behind frame 1's
// image (that job ended with 1 and no word of the interrupt, found by an animator).
TEST_F(Resume, AnInterruptDuringAWritesRetriesSaysWhatIsNotWritten) {
  for (const auto& [frame, after] : {std::pair{1, 0.0}, std::pair{2, 1.5}}) {
    SCOPED_TRACE(frame);
    std::string err;
    EXPECT_EQ(InterruptFrame(*dir_, frame, after, "--fault-fail-writes", "1000", &err),
              128 + SIGINT) << err;
    EXPECT_NE(err.find("interrupted (SIGINT)"), std::string::npos) << err;
    EXPECT_NE(err.find(dir_->File("frame-0.exr") + ": cannot write EXR"), std::string::npos) << err;
    EXPECT_NE(err.find("(free some space; Ctrl-C gives up)"), std::string::npos) << err;
    if (frame == 2) {
      EXPECT_NE(err.find(dir_->File("frame-1.exr") + " is not written either"), std::string::npos)
          << err;
    }
    EXPECT_FALSE(std::filesystem::exists(dir_->File("frame-0.exr")));
  }
}

// Two renders of one output at once (the same scene run twice): both ended with exit 0, the
// last image written won, and each replaced the other's checkpoints. The second is refused
// while the first holds the output's lock; the lock's file goes with the first.
TEST_F(Resume, TwoRendersOfOneOutputAreRefused) {
  const std::string out = dir_->File("shared.exr");
  const std::string lock = dir_->File(".shared.exr.lock");  // (one camera: frame 0's file is the output)
  for (int np : {0, 3}) {
    SCOPED_TRACE(np);
    std::vector<std::string> argv;
    if (np > 0) argv = {RAYSTACK_MPIRUN, "--allow-run-as-root", "--oversubscribe", "-np", std::to_string(np)};
    for (const std::string& a : {kRaystackBinary, std::string("render"), dir_->File("scene.json"),
                                 std::string("--threads"), std::string("1"), std::string("--output"),
                                 out, std::string("--no-png"), std::string("--spp"), std::string("400"),
                                 std::string("--checkpoint-s"), std::string("0.05")})
      argv.push_back(a);
    master::preview::testing::BackgroundProcess first(argv, dir_->path());
    // Its first checkpoint written (a partial frame at the output): the second render must
    // still say that another render writes it, not that a stopped run left it (a review).
    for (int i = 0; i < 3000 && !(std::filesystem::exists(lock) && std::filesystem::exists(out)); ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    ASSERT_TRUE(std::filesystem::exists(lock)) << first.out() << first.err();
    ASSERT_TRUE(std::filesystem::exists(out)) << first.out() << first.err();
    const ProcessResult second = Render(out, np);
    EXPECT_NE(second.exit_code, 0);
    EXPECT_NE(second.err.find("another raystack render is writing this output now"),
              std::string::npos) << second.err;
    ASSERT_EQ(first.Wait(), 0) << first.err();
    EXPECT_FALSE(std::filesystem::exists(lock));
    const ProcessResult third = Render(out, np);
    EXPECT_EQ(third.exit_code, 0) << third.err;
  }
}

// A checkpoint that cannot be written (here: the first two, as on a full disk) is logged and
// tried again at the next interval; it never ends the job and costs no pixel. Killing the job
// right after its first checkpoint that did get written proves a later one was tried.
TEST_F(Resume, AFailedCheckpointIsLoggedAndTheNextOneIsWritten) {
  const std::string expected = Uninterrupted();
  ASSERT_FALSE(expected.empty());
  for (int np : {0, 3}) {
    SCOPED_TRACE("np " + std::to_string(np));
    auto failures = [](const std::string& err) {
      size_t n = 0;
      for (size_t at = err.find("--fault-fail-checkpoints"); at != std::string::npos;
           at = err.find("--fault-fail-checkpoints", at + 1))
        ++n;
      return n;
    };
    std::vector<std::string> failing = WholeTiles();
    failing.insert(failing.end(), {"--fault-fail-checkpoints", "2"});
    const std::string out = dir_->File("failing" + std::to_string(np) + ".exr");
    const ProcessResult r = Render(out, np, failing);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(failures(r.err), 2u) << r.err;
    EXPECT_NE(r.err.find(out + ": cannot write"), std::string::npos) << "names the file: " << r.err;
    EXPECT_TRUE(Slurp(out) == expected);

    failing.insert(failing.end(), {"--fault-kill-after-checkpoints", "1"});
    const std::string killed = dir_->File("failing-killed" + std::to_string(np) + ".exr");
    const ProcessResult died = Render(killed, np, failing);
    ASSERT_NE(died.exit_code, 0) << "the third checkpoint was never written: " << died.err;
    EXPECT_EQ(failures(died.err), 2u) << died.err;
    Expected<image::ImageLayers> checkpoint = image::ReadExr(killed);
    ASSERT_TRUE(checkpoint.ok()) << checkpoint.status().message();
  }
}

TEST_F(Resume, ACheckpointOfAnotherFrameIsRefusedNamingIt) {
  image::ImageLayers other;
  other.Resize(10, 10);
  ASSERT_TRUE(image::WriteExr(dir_->File("other.exr"), other).ok());
  const ProcessResult r = Render(dir_->File("other.exr"), 0, {"--resume"});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("other.exr: the checkpoint is 10x10, this frame 96x64"), std::string::npos)
      << r.err;
}

// A checkpoint records what rendered it (store, camera, lights, materials, integrator): after
// the scene was edited (here its light moved), or from another program, --resume refuses it
// rather than keep the old pixels as this scene's; the scene as it was resumes from it.
TEST_F(Resume, ACheckpointOfAnEditedSceneOrAnotherProgramIsRefused) {
  const std::string out = dir_->File("edited.exr");
  ASSERT_EQ(Render(out, 0).exit_code, 0);
  const std::string scene = Slurp(dir_->File("scene.json"));
  std::string moved = scene;
  moved.replace(moved.find("[3, 8, 4]"), 9, "[3, 9, 4]");
  std::ofstream(dir_->File("scene.json")) << moved;
  ProcessResult r = Render(out, 0, {"--resume"});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("edited.exr: rendered from another scene"), std::string::npos) << r.err;
  // It says what differs (found by a helper reading the docs: a build's checkpoint was
  // refused as "another scene" without a word of the build).
  // (A complete frame is "the frame", a checkpoint "checkpoint": an operator read a finished
  // frame called a checkpoint.)
  EXPECT_NE(r.err.find("the frame: 'light: position 3 8 4"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("this run: 'light: position 3 9 4"), std::string::npos) << r.err;
  // The same store written another way is the same store.
  std::string spelled = scene;
  spelled.replace(spelled.find("\"store\": \"store\""), 16, "\"store\": \"./store\"");
  std::ofstream(dir_->File("scene.json")) << spelled;
  r = Render(out, 0, {"--resume"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("6144 of 6144 pixels finished"), std::string::npos) << r.out;

  Expected<image::ImageLayers> image = image::ReadExr(out);
  ASSERT_TRUE(image.ok()) << image.status().message();
  EXPECT_NE(image->provenance.find("light: position 3 8 4"), std::string::npos) << image->provenance;
  image->provenance.clear();
  ASSERT_TRUE(image::WriteExr(out, *image).ok());
  r = Render(out, 0, {"--resume"});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("edited.exr: it does not say what rendered it"), std::string::npos) << r.err;

  // A store rebuilt in place (another model at the same path) is another store.
  ASSERT_EQ(Render(out, 0).exit_code, 0);
  const prep::testing::ProcessResult rebuilt = RunProcess(
      {prep::testing::kPrepBinary, "--generate", "sphere:5000", "-o", dir_->File("store"), "-q"},
      dir_->path());
  ASSERT_EQ(rebuilt.exit_code, 0) << rebuilt.err;
  r = Render(out, 0, {"--resume"});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("edited.exr: rendered from another scene"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("the frame: 'store "), std::string::npos) << r.err;

  // Another build's checkpoint says so; another build's complete frame of the same scene is
  // kept as it is, as every complete frame is (found by an operator: a job requeued after a
  // rebuild was refused on its finished frames).
  ASSERT_EQ(Render(out, 0).exit_code, 0);
  image = image::ReadExr(out);
  ASSERT_TRUE(image.ok()) << image.status().message();
  const size_t build = image->provenance.find("build ");
  ASSERT_NE(build, std::string::npos);
  image->provenance.insert(build + 6, "older-");
  ASSERT_TRUE(image::WriteExr(out, *image).ok());
  const std::string older = Slurp(out);
  r = Render(out, 0, {"--resume"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("kept " + out + " (complete)"), std::string::npos) << r.out;
  EXPECT_TRUE(Slurp(out) == older) << "the complete frame is left as it is";
  image->partial = true;  // the same pixels as a checkpoint: continued by its own build only
  ASSERT_TRUE(image::WriteExr(out, *image).ok());
  r = Render(out, 0, {"--resume"});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("checkpoint: 'build older-"), std::string::npos) << r.err;

  // A record that is a prefix of the run's, without its last newline (found by the day's
  // review: the comparison read past its end and the render aborted).
  std::filesystem::remove(out);  // (the checkpoint above: a run without --resume keeps off it)
  ASSERT_EQ(Render(out, 0).exit_code, 0);
  image = image::ReadExr(out);
  ASSERT_TRUE(image.ok()) << image.status().message();
  const size_t second = image->provenance.find('\n', image->provenance.find('\n') + 1);
  ASSERT_NE(second, std::string::npos);
  image->provenance.resize(second);
  ASSERT_TRUE(image::WriteExr(out, *image).ok());
  r = Render(out, 0, {"--resume"});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("the frame: ''; this run: 'store "), std::string::npos) << r.err;
}

TEST_F(Resume, WithoutACheckpointEverythingIsRendered) {
  const ProcessResult r = Render(dir_->File("fresh.exr"), 0, {"--resume"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("no checkpoint at " + dir_->File("fresh.exr") + ", every tile to render"),
            std::string::npos) << r.out;
}

// Under mpirun --enable-recovery the job's exit code is 0 whatever happened (found by an
// operator: deploy/run-default.sh "succeeded" with the output a folder), so scripts check the
// image: raystack-info IMAGE.exr exits 0 only for a complete frame, without OpenEXR's tools.
TEST_F(Resume, RaystackInfoTellsACompleteFrameFromAPartialOne) {
  const ProcessResult full = Render(dir_->File("done.exr"), 0);
  ASSERT_EQ(full.exit_code, 0) << full.err;
  ProcessResult info = RunProcess({prep::testing::kInfoBinary, dir_->File("done.exr")}, dir_->path());
  EXPECT_EQ(info.exit_code, 0) << info.err;
  EXPECT_NE(info.out.find("state            complete"), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("size             96 x 64"), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("samples/pixel    3 to 3"), std::string::npos) << info.out;
  Expected<image::ImageLayers> image = image::ReadExr(dir_->File("done.exr"));
  ASSERT_TRUE(image.ok());
  // Each layer's range and mean, and what is not finite (a researcher wrote a reader for it).
  size_t misses = 0;
  for (const float z : image->z) misses += std::isinf(z);
  EXPECT_NE(info.out.find("layer Z          "), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("; " + std::to_string(misses) + " infinite\n"), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("layer A          0 to 1, mean "), std::string::npos) << info.out;
  EXPECT_NE(info.out.find("layer variance   "), std::string::npos) << info.out;
  image->partial = true;  // as a checkpoint is written
  ASSERT_TRUE(image::WriteExr(dir_->File("checkpoint.exr"), *image).ok());
  info = RunProcess({prep::testing::kInfoBinary, dir_->File("checkpoint.exr")}, dir_->path());
  EXPECT_EQ(info.exit_code, 1);
  EXPECT_NE(info.err.find("a partial frame"), std::string::npos) << info.err;
  EXPECT_NE(info.err.find("--resume continues it"), std::string::npos) << info.err;
  image->partial = false;
  image->provenance.clear();  // another program's EXR
  ASSERT_TRUE(image::WriteExr(dir_->File("other.exr"), *image).ok());
  info = RunProcess({prep::testing::kInfoBinary, dir_->File("other.exr")}, dir_->path());
  EXPECT_EQ(info.exit_code, 1);
  EXPECT_NE(info.err.find("not a frame raystack render wrote"), std::string::npos) << info.err;
  info = RunProcess({prep::testing::kInfoBinary, dir_->File("scene.json")}, dir_->path());
  EXPECT_EQ(info.exit_code, 1);
  EXPECT_NE(info.err.find(dir_->File("scene.json") + " is neither a block store"),
            std::string::npos) << info.err;  // not "cannot read EXR" (a new user's scene file)
}

// What a resumed run renders, for its progress (the bar and the preview): a finished pixel in a
// tile still to render is rendered again, so it is not done already. The preview took every
// restored pixel as done, and with the rendered samples counted them twice: its progress reached
// 100% while tiles were still rendering; the bar counted the whole frame and ended short of it.
TEST(ResumeProgress, OnlyTilesNoLongerRenderedCountAsDone) {
  constexpr int kWidth = 40, kHeight = 24, kTile = 8;
  constexpr uint32_t kSpp = 4;
  for (const bool coarse : {false, true}) {
    render::FramePlan plan = render::MakeFramePlan(kWidth, kHeight, kTile, kSpp, /*pass_spp=*/0,
                                                   render::PixelOrder::kPriority, coarse);
    master::ResumePlan resume;
    resume.width = kWidth;
    resume.finished.assign(static_cast<size_t>(kWidth) * kHeight, 0);
    // The left half finished; in the right half every other pixel, as a checkpoint catches tiles
    // whose pixels finish one by one.
    for (int y = 0; y < kHeight; ++y)
      for (int x = 0; x < kWidth; ++x)
        if (x < kWidth / 2 || (x + y) % 2 == 0) {
          resume.finished[static_cast<size_t>(y) * kWidth + x] = 1;
          resume.kept_pixels.push_back(static_cast<uint32_t>(y * kWidth + x));
        }
    master::DropFinishedTiles(resume, &plan);
    // Every (pixel, sample) a remaining tile renders, and the kept pixels no tile touches.
    std::vector<uint32_t> rendered(static_cast<size_t>(kWidth) * kHeight, 0);
    for (size_t i = 0; i < plan.sweeps.size(); ++i)
      for (const render::Tile& t : plan.Tiles(i))
        for (int y = t.y0; y < t.y1; ++y)
          for (int x = t.x0; x < t.x1; ++x)
            if (t.HasRank(x, y))
              rendered[static_cast<size_t>(y) * kWidth + x] +=
                  (t.sample_end == 0 ? kSpp : t.sample_end) - t.sample_begin;
    uint64_t to_render = 0, untouched = 0;
    for (size_t i = 0; i < rendered.size(); ++i) {
      to_render += rendered[i];
      if (resume.finished[i]) untouched += kSpp - rendered[i];
      else EXPECT_EQ(rendered[i], kSpp) << "an unfinished pixel is rendered whole";
    }
    EXPECT_EQ(plan.samples_to_render(), to_render) << "coarse " << coarse;
    EXPECT_EQ(plan.total_samples() - plan.samples_to_render(), untouched) << "coarse " << coarse;
    // The case of the bug: some kept pixels are rendered again, so fewer samples are done
    // already than the kept pixels hold.
    EXPECT_LT(untouched, resume.kept_pixels.size() * kSpp) << "coarse " << coarse;
  }
}

}  // namespace
}  // namespace raystack::testing
