// The master's frame writer: images queued while the next frame renders are all written, in
// order, before Finish returns or the writer ends; a failed write is reported, not lost; a frame
// written while others render leaves the cores to them.

#include "master/frame_writer.h"

#include <gtest/gtest.h>

#include <atomic>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "common/base/temp_dir.h"
#include "common/base/thread_cpu.h"
#include "common/image/exr_io.h"

namespace raystack::testing {
namespace {

image::ImageLayers Flat(int width, int height, float value) {
  image::ImageLayers l;
  l.width = width;
  l.height = height;
  l.rgba.assign(static_cast<size_t>(width) * height * 4, value);
  return l;
}

// An image zlib has work to do on: RGBA from a simple hash of the position.
image::ImageLayers Varied(int width, int height) {
  image::ImageLayers l = Flat(width, height, 0);
  for (size_t i = 0; i < l.rgba.size(); ++i)
    l.rgba[i] = static_cast<float>((i * 2654435761u) % 100003u) * 1e-3f;
  return l;
}

master::FrameWriter::Image ImageAt(const std::string& exr, float value) {
  master::FrameWriter::Image i;
  i.exr = exr;
  i.layers = Flat(32, 16, value);
  return i;
}

TEST(FrameWriter, EveryQueuedImageIsWrittenBeforeFinishReturns) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  auto path = [&](int f) {
    std::string name = "f";
    name += std::to_string(f);
    name += ".exr";
    return dir->File(name);
  };
  master::FrameWriter writer(false);
  for (int f = 0; f < 5; ++f) ASSERT_TRUE(writer.Write(ImageAt(path(f), 0.25f * f)).ok());
  ASSERT_TRUE(writer.Finish().ok());
  for (int f = 0; f < 5; ++f) {
    Expected<image::ImageLayers> read = image::ReadExr(path(f));
    ASSERT_TRUE(read.ok()) << read.status().message();
    EXPECT_EQ(read->rgba[0], 0.25f * f);
  }
}

TEST(FrameWriter, WhatIsQueuedIsWrittenWhenTheWriterEnds) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  {
    master::FrameWriter writer(false);
    ASSERT_TRUE(writer.Write(ImageAt(dir->File("a.exr"), 1)).ok());
    ASSERT_TRUE(writer.Write(ImageAt(dir->File("b.exr"), 2)).ok());
  }
  EXPECT_TRUE(image::ReadExr(dir->File("a.exr")).ok());
  EXPECT_TRUE(image::ReadExr(dir->File("b.exr")).ok());
}

// The nice value of each of this process's threads named `name` (every thread when empty).
std::vector<int> NiceOfThreads(const std::string& name = "") {
  std::vector<int> nice;
  for (const auto& task : std::filesystem::directory_iterator("/proc/self/task")) {
    std::ifstream comm(task.path() / "comm");
    std::string thread_name;
    std::getline(comm, thread_name);
    if (!name.empty() && thread_name != name) continue;
    std::ifstream stat(task.path() / "stat");
    std::string line;
    std::getline(stat, line);
    // Fields after the command, which is in parentheses: state is field 3, nice field 19.
    std::istringstream fields(line.substr(line.rfind(')') + 2));
    std::string field;
    for (int i = 3; i <= 19; ++i) fields >> field;
    nice.push_back(std::stoi(field));
  }
  return nice;
}

// A frame written while the next renders is compressed by a thread at nice 19, itself (not by
// OpenEXR's pool at the job's priority); the last frame at the job's priority, on every core.
TEST(FrameWriter, AFrameWrittenWhileOthersRenderLeavesThemTheCores) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  const int own = getpriority(PRIO_PROCESS, 0);
  master::FrameWriter writer(false);
  ASSERT_TRUE(writer.Write(ImageAt(dir->File("last.exr"), 1)).ok());
  ASSERT_TRUE(writer.Finish().ok());
  // The writer's thread, and OpenEXR's, which it started (they inherit its name and priority).
  const std::vector<int> writers = NiceOfThreads("rs-write");
  ASSERT_FALSE(writers.empty());
  EXPECT_EQ(std::count(writers.begin(), writers.end(), own), std::ssize(writers));

  master::FrameWriter::Image background = ImageAt(dir->File("f0.exr"), 2);
  background.background = true;
  background.layers = Varied(512, 512);  // enough compression to see where it runs
  int nice = own;
  double compressed_on_thread = 0;
  Status written = Status::Error("not written");
  background.done = [&](const Status& s) {  // on the thread that wrote it
    written = s;
    nice = getpriority(PRIO_PROCESS, static_cast<id_t>(gettid()));
    compressed_on_thread = ThreadCpuSeconds();
  };
  const double process_began = ProcessCpuSeconds();
  ASSERT_TRUE(writer.Write(std::move(background)).ok());
  ASSERT_TRUE(writer.Finish().ok());
  const double in_process = ProcessCpuSeconds() - process_began;
  ASSERT_TRUE(written.ok()) << written.message();
  EXPECT_EQ(nice, 19);
  EXPECT_GE(compressed_on_thread, 0.9 * in_process)
      << "the nice 19 thread spent " << compressed_on_thread << " CPU-s of " << in_process;
  Expected<image::ImageLayers> read = image::ReadExr(dir->File("f0.exr"));
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->rgba, Varied(512, 512).rgba);

  // The next last frame: the writer's thread and OpenEXR's threads keep the job's priority.
  ASSERT_TRUE(writer.Write(ImageAt(dir->File("f1.exr"), 3)).ok());
  ASSERT_TRUE(writer.Finish().ok());
  const std::vector<int> nice_now = NiceOfThreads();
  EXPECT_EQ(std::count(nice_now.begin(), nice_now.end(), own), std::ssize(nice_now))
      << "no thread stays at 19";
  EXPECT_EQ(getpriority(PRIO_PROCESS, 0), own);
}

// A written image's layers, a frame's or a checkpoint's, come back for the next resolve (memory
// already mapped), and each comes back once.
TEST(FrameWriter, AWrittenImagesLayersComeBackOnce) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  master::FrameWriter writer(false);
  EXPECT_TRUE(writer.TakeSpare().rgba.empty());
  ASSERT_TRUE(writer.Write(ImageAt(dir->File("f0.exr"), 5)).ok());
  ASSERT_TRUE(writer.Finish().ok());
  const image::ImageLayers spare = writer.TakeSpare();
  EXPECT_EQ(spare.rgba, ImageAt(dir->File("x.exr"), 5).layers.rgba);
  EXPECT_TRUE(writer.TakeSpare().rgba.empty());
  master::FrameWriter::Image checkpoint = ImageAt(dir->File("f1.exr"), 6);
  checkpoint.done = [](const Status&) {};
  ASSERT_TRUE(writer.Write(std::move(checkpoint)).ok());
  ASSERT_TRUE(writer.Finish().ok());
  EXPECT_EQ(writer.TakeSpare().rgba, ImageAt(dir->File("x.exr"), 6).layers.rgba);
  EXPECT_TRUE(writer.TakeSpare().rgba.empty());
}

// A frame's image that cannot be written is tried again for retry_seconds, then reported,
// naming the file (here after one more try, 1 s later: the tries are 1, 2, 4 ... s apart).
TEST(FrameWriter, AFailedWriteIsReportedNamingTheFile) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  master::FrameWriter writer(false, 0, /*retry_seconds=*/0.5);
  const std::string bad = dir->File("no-such-folder/x.exr");
  ASSERT_TRUE(writer.Write(ImageAt(bad, 1)).ok());  // queued: the failure comes later
  const Status finished = writer.Finish();
  ASSERT_FALSE(finished.ok());
  EXPECT_NE(finished.message().find("no-such-folder/x.exr"), std::string::npos) << finished.message();
  EXPECT_NE(finished.message().find("(tried for 1 s)"), std::string::npos) << finished.message();
  // Later writes are refused with the same error.
  const Status next = writer.Write(ImageAt(dir->File("y.exr"), 1));
  EXPECT_FALSE(next.ok());
}

// --stats' record of a frame goes once its image is written (found by an operator: after a
// kill -9, the statistics listed frames whose EXR was missing or unfinished): `written` is called
// after the write, from the writer's thread, and never for an image that could not be written.
TEST(FrameWriter, WrittenIsCalledOnceTheImageIsOnDiskAndNeverForAFailedOne) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  std::atomic<int> calls{0};
  std::atomic<bool> on_disk_then{false};
  master::FrameWriter writer(false, 0, /*retry_seconds=*/0.5);
  master::FrameWriter::Image good = ImageAt(dir->File("good.exr"), 1);
  good.written = [&] {
    on_disk_then = image::ReadExr(dir->File("good.exr")).ok();
    ++calls;
  };
  ASSERT_TRUE(writer.Write(std::move(good)).ok());
  master::FrameWriter::Image bad = ImageAt(dir->File("no-such-folder/x.exr"), 1);
  bad.written = [&] { calls += 100; };
  ASSERT_TRUE(writer.Write(std::move(bad)).ok());
  EXPECT_FALSE(writer.Finish().ok());
  EXPECT_EQ(calls, 1);
  EXPECT_TRUE(on_disk_then);
}

}  // namespace
}  // namespace raystack::testing
