// --checkpoint-s: a checkpoint is resolved on the master's loop and written by the frame
// writer, so the loop never waits for the disk; it never waits for room in the writer either
// (a checkpoint that cannot be queued is tried at the next call); it is always written before
// the frame's final image at the same path; and a failed one is not the job's error.

#include "master/checkpoints.h"

#include <gtest/gtest.h>

#include <condition_variable>
#include <filesystem>
#include <mutex>
#include <thread>

#include "common/base/temp_dir.h"
#include "common/image/exr_io.h"
#include "common/render/film.h"

namespace raystack::testing {
namespace {

// A 4x2 film whose pixel 0 has one sample of radiance `value`.
void Fill(render::Film* film, float value) {
  film->Clear();
  render::SampleResult s{};
  s.pixel = 0;
  s.rgb[0] = s.rgb[1] = s.rgb[2] = value;
  s.hit = 1;
  film->Merge({&s, 1});
}

master::FrameWriter::Image Flat(const std::string& exr, float value) {
  master::FrameWriter::Image i;
  i.exr = exr;
  i.layers.width = 4;
  i.layers.height = 2;
  i.layers.rgba.assign(4 * 2 * 4, value);
  return i;
}

// Holds the writer's thread inside an image's `done` until Release.
class Gate {
 public:
  master::FrameWriter::Image Holding(master::FrameWriter::Image image) {
    image.done = [this](const Status&) {
      std::unique_lock lock(mu_);
      entered_ = true;
      cv_.notify_all();
      cv_.wait(lock, [&] { return open_; });
    };
    return image;
  }
  void WaitEntered() {
    std::unique_lock lock(mu_);
    cv_.wait(lock, [&] { return entered_; });
  }
  void Release() {
    std::lock_guard lock(mu_);
    open_ = true;
    cv_.notify_all();
  }

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  bool entered_ = false, open_ = false;
};

// Calls Maybe once a checkpoint of `every_s` is due.
void MaybeWhenDue(master::Checkpoints* checkpoints, const render::Film& film, double every_s) {
  std::this_thread::sleep_for(std::chrono::duration<double>(every_s * 1.5));
  checkpoints->Maybe(film, 1);
}

TEST(Checkpoints, AreWrittenByTheWriterWhileTheLoopGoesOn) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  render::Film film(4, 2);
  Fill(&film, 5);
  master::FrameWriter writer(false);
  Gate gate;
  ASSERT_TRUE(writer.Write(gate.Holding(Flat(dir->File("earlier.exr"), 1))).ok());
  gate.WaitEntered();  // the writer is busy (a slow disk)
  const std::string path = dir->File("frame.exr");
  master::Checkpoints checkpoints(0.01, path, "test", &writer);
  MaybeWhenDue(&checkpoints, film, 0.01);  // returns at once: queued, not written
  EXPECT_FALSE(std::filesystem::exists(path));
  gate.Release();
  ASSERT_TRUE(writer.Finish().ok());
  Expected<image::ImageLayers> read = image::ReadExr(path);
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->rgba[0], 5.0f);
}

// A checkpoint resolves into the layers of the last image written (memory already mapped: new
// layers cost a page fault a page), and its own come back after it is written.
TEST(Checkpoints, ResolveIntoTheLastWrittenImagesLayers) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  render::Film film(4, 2);
  Fill(&film, 5);
  master::FrameWriter writer(false);
  ASSERT_TRUE(writer.Write(Flat(dir->File("earlier.exr"), 1)).ok());
  ASSERT_TRUE(writer.Finish().ok());  // its layers are the writer's spare now
  Gate gate;
  ASSERT_TRUE(writer.Write(gate.Holding(Flat(dir->File("slow.exr"), 2))).ok());
  gate.WaitEntered();  // nothing comes back while this one is held
  master::Checkpoints checkpoints(0.01, dir->File("frame.exr"), "test", &writer);
  MaybeWhenDue(&checkpoints, film, 0.01);
  EXPECT_TRUE(writer.TakeSpare().rgba.empty()) << "the checkpoint took the spare layers";
  gate.Release();
  ASSERT_TRUE(writer.Finish().ok());
  const image::ImageLayers back = writer.TakeSpare();  // the checkpoint's, written last
  ASSERT_FALSE(back.rgba.empty());
  EXPECT_EQ(back.rgba[0], 5.0f);
}

TEST(Checkpoints, WaitForNoRoomButAreTriedAtTheNextCall) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  render::Film film(4, 2);
  Fill(&film, 7);
  master::FrameWriter writer(false);
  Gate gate;
  ASSERT_TRUE(writer.Write(gate.Holding(Flat(dir->File("a.exr"), 1))).ok());
  gate.WaitEntered();
  ASSERT_TRUE(writer.Write(Flat(dir->File("b.exr"), 2)).ok());  // queued: no room left
  const std::string path = dir->File("frame.exr");
  master::Checkpoints checkpoints(0.01, path, "test", &writer);
  MaybeWhenDue(&checkpoints, film, 0.01);  // would hang here if it waited for room
  gate.Release();
  ASSERT_TRUE(writer.Finish().ok());
  EXPECT_FALSE(std::filesystem::exists(path)) << "skipped, the writer had no room";
  checkpoints.Maybe(film, 1);  // still due: written now
  ASSERT_TRUE(writer.Finish().ok());
  Expected<image::ImageLayers> read = image::ReadExr(path);
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->rgba[0], 7.0f);
}

TEST(Checkpoints, TheFramesFinalImageReplacesItsCheckpoints) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  render::Film film(4, 2);
  master::FrameWriter writer(false);
  const std::string path = dir->File("frame.exr");
  {
    master::Checkpoints checkpoints(0.005, path, "test", &writer);
    for (int i = 1; i <= 5; ++i) {
      Fill(&film, static_cast<float>(i));
      MaybeWhenDue(&checkpoints, film, 0.005);
    }
  }  // the frame ends with its checkpoints perhaps still queued
  ASSERT_TRUE(writer.Write(Flat(path, 9)).ok());
  ASSERT_TRUE(writer.Finish().ok());
  Expected<image::ImageLayers> read = image::ReadExr(path);
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->rgba[0], 9.0f);
}

TEST(Checkpoints, AFailedOneIsNotTheJobsError) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  render::Film film(4, 2);
  Fill(&film, 1);
  master::FrameWriter writer(false);
  master::Checkpoints checkpoints(0.01, dir->File("no-such-folder/frame.exr"), "test", &writer);
  MaybeWhenDue(&checkpoints, film, 0.01);
  EXPECT_TRUE(writer.Finish().ok());
  EXPECT_TRUE(writer.Write(Flat(dir->File("final.exr"), 1)).ok());
  EXPECT_TRUE(writer.Finish().ok());
}

// The images of the frames that finished before an interrupt, still queued behind a slow disk,
// are written before the process ends (found by an animator: Ctrl-C lost two finished frames
// the writer still held). The frame rendering is written too, to look at, though no pixel of it
// has all its samples (a user's Ctrl-C in the first passes left no image of minutes of work).
TEST(Checkpoints, TheFinalOneWaitsForTheFinishedFramesQueuedBefore) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  render::Film film(4, 2);
  Fill(&film, 5);  // pixel 0 has 1 sample of 4: no pixel finished
  master::FrameWriter writer(false, 0, master::FrameWriter::kRetrySeconds, /*slow_s=*/0.3);
  ASSERT_TRUE(writer.Write(Flat(dir->File("frame-0.exr"), 1)).ok());
  ASSERT_TRUE(writer.Write(Flat(dir->File("frame-1.exr"), 2)).ok());
  const std::string path = dir->File("frame-2.exr");
  master::Checkpoints checkpoints(0, path, "test", &writer);
  Expected<master::Checkpoints::Kept> kept = checkpoints.Final(film, 4);
  ASSERT_TRUE(kept.ok()) << kept.status().message();
  EXPECT_EQ(kept->finished, 0u);
  EXPECT_TRUE(kept->written);
  EXPECT_TRUE(image::IsPartialFrame(path)) << "the frame so far, to look at";
  for (const char* name : {"frame-0.exr", "frame-1.exr"}) {
    Expected<image::ImageLayers> read = image::ReadExr(dir->File(name));
    EXPECT_TRUE(read.ok()) << name << ": " << read.status().message();
  }
}

// ... but a finished image of an earlier run there is not replaced by a frame --resume could keep
// nothing of; with a pixel to keep, it is.
TEST(Checkpoints, TheFinalOneKeepsAFinishedImageWhenItHasNothingToKeep) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  const std::string path = dir->File("frame.exr");
  master::FrameWriter writer(false, 0, master::FrameWriter::kRetrySeconds, 0);
  ASSERT_TRUE(writer.Write(Flat(path, 1)).ok());
  ASSERT_TRUE(writer.Finish().ok());
  render::Film film(4, 2);
  Fill(&film, 5);  // pixel 0 has 1 sample
  master::Checkpoints checkpoints(0, path, "test", &writer);
  Expected<master::Checkpoints::Kept> kept = checkpoints.Final(film, 4);
  ASSERT_TRUE(kept.ok()) << kept.status().message();
  EXPECT_FALSE(kept->written);
  EXPECT_FALSE(image::IsPartialFrame(path)) << "the earlier finished image stays";
  // Nor by a periodic checkpoint (the day's review: the first one replaced it).
  master::Checkpoints periodic(1e-9, path, "test", &writer);
  std::this_thread::sleep_for(std::chrono::milliseconds(1));
  periodic.Maybe(film, 4);
  ASSERT_TRUE(writer.Finish().ok());
  EXPECT_FALSE(image::IsPartialFrame(path)) << "the earlier finished image stays";
  std::this_thread::sleep_for(std::chrono::milliseconds(1));
  periodic.Maybe(film, 1);  // pixel 0 finished: worth a checkpoint
  ASSERT_TRUE(writer.Finish().ok());
  EXPECT_TRUE(image::IsPartialFrame(path));
  kept = checkpoints.Final(film, 1);
  ASSERT_TRUE(kept.ok()) << kept.status().message();
  EXPECT_EQ(kept->finished, 1u);
  EXPECT_TRUE(kept->written);
  EXPECT_TRUE(image::IsPartialFrame(path));
}

// An earlier frame's failed write is what the final checkpoint returns (the interrupt's message
// says it), and the frame after it that failed too is named in it.
TEST(Checkpoints, TheFinalOneSaysWhichEarlierFramesAreNotWritten) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  render::Film film(4, 2);
  Fill(&film, 5);
  // Both fail, as on a full disk; frame 1 is queued while frame 0 is written (slowly).
  master::FrameWriter writer(false, /*fail_first=*/2, /*retry_seconds=*/0, /*slow_s=*/0.2);
  ASSERT_TRUE(writer.Write(Flat(dir->File("frame-0.exr"), 1)).ok());
  ASSERT_TRUE(writer.Write(Flat(dir->File("frame-1.exr"), 2)).ok());
  master::Checkpoints checkpoints(0, dir->File("frame-2.exr"), "test", &writer);
  Expected<master::Checkpoints::Kept> kept = checkpoints.Final(film, 1);
  ASSERT_FALSE(kept.ok());
  const std::string said = kept.status().message();
  EXPECT_NE(said.find("an earlier frame's image was not written: " + dir->File("frame-0.exr")),
            std::string::npos) << said;
  EXPECT_NE(said.find(dir->File("frame-1.exr") + " is not written either"), std::string::npos)
      << said;
  EXPECT_FALSE(std::filesystem::exists(dir->File("frame-2.exr")));
}

}  // namespace
}  // namespace raystack::testing
