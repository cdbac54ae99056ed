// The master's frame writer: images queued while the next frame renders are all written, in
// order, before Finish returns or the writer ends; a failed write is reported, not lost.

#include "master/frame_writer.h"

#include <gtest/gtest.h>

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
