// The master's frame writer: images queued while the next frame renders are all written, in
// order, before Finish returns or the writer ends; a failed write is reported, not lost; a frame
// written while others render leaves the cores to them.

#include "master/frame_writer.h"

#include <gtest/gtest.h>
#include <sys/resource.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "common/base/temp_dir.h"
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

TEST(FrameWriter, AFrameWrittenWhileOthersRenderLeavesThemTheCores) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  const int own = getpriority(PRIO_PROCESS, 0);
  master::FrameWriter writer(false);
  ASSERT_TRUE(writer.Write(ImageAt(dir->File("last.exr"), 1)).ok());
  ASSERT_TRUE(writer.Finish().ok());
  // A last frame: written at the job's priority.
  EXPECT_EQ(NiceOfThreads("rs-write"), std::vector<int>{own});
  master::FrameWriter::Image background = ImageAt(dir->File("f0.exr"), 2);
  background.background = true;
  ASSERT_TRUE(writer.Write(std::move(background)).ok());
  ASSERT_TRUE(writer.Finish().ok());
  EXPECT_EQ(NiceOfThreads("rs-write"), std::vector<int>{19});
  Expected<image::ImageLayers> read = image::ReadExr(dir->File("f0.exr"));
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->rgba[0], 2.0f);
  // The next last frame is compressed on every core by OpenEXR's threads: they keep the job's
  // priority (started with the writer, not by its thread once lowered), as every other thread.
  ASSERT_TRUE(writer.Write(ImageAt(dir->File("f1.exr"), 3)).ok());
  ASSERT_TRUE(writer.Finish().ok());
  const std::vector<int> nice = NiceOfThreads();
  EXPECT_EQ(std::count(nice.begin(), nice.end(), 19), 1) << "only the writer's thread is at 19";
  EXPECT_EQ(getpriority(PRIO_PROCESS, 0), own);
}

TEST(FrameWriter, AFailedWriteIsReportedNamingTheFile) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  master::FrameWriter writer(false);
  const std::string bad = dir->File("no-such-folder/x.exr");
  ASSERT_TRUE(writer.Write(ImageAt(bad, 1)).ok());  // queued: the failure comes later
  const Status finished = writer.Finish();
  ASSERT_FALSE(finished.ok());
  EXPECT_NE(finished.message().find("no-such-folder/x.exr"), std::string::npos) << finished.message();
  // Later writes are refused with the same error.
  const Status next = writer.Write(ImageAt(dir->File("y.exr"), 1));
  EXPECT_FALSE(next.ok());
}

}  // namespace
}  // namespace raystack::testing
