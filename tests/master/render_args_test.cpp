#include "master/render_args.h"

#include <gtest/gtest.h>

#include "slave/block_loader.h"

namespace raystack::master {
namespace {

// Found by a helper reading the docs: on a node of 128 hardware threads, `raystack render`
// without --threads failed ("--threads must be in [1, 64], got 128") while the help said the
// default was all cores.
TEST(RenderArgs, TheDefaultThreadsAreTheCoresUpToWhatTheLoaderServes) {
  EXPECT_EQ(DefaultRayThreads(0), 1);  // hardware_concurrency may not know
  EXPECT_EQ(DefaultRayThreads(2), 2);
  EXPECT_EQ(DefaultRayThreads(64), slave::BlockLoader::kMaxRayThreads);
  EXPECT_EQ(DefaultRayThreads(128), slave::BlockLoader::kMaxRayThreads);
  EXPECT_EQ(DefaultRayThreads(100000), slave::BlockLoader::kMaxRayThreads);
}

// Found by a scale review: on a 128-core node the default of 64 threads left half the cores idle
// without a word. It is said now, with what to do.
TEST(RenderArgs, CoresBeyondWhatOneSlaveRunsAreSaid) {
  EXPECT_EQ(RayThreadsCapNote(2), "");
  EXPECT_EQ(RayThreadsCapNote(64), "");
  const std::string note = RayThreadsCapNote(128);
  EXPECT_NE(note.find("may use 128 cores and renders with 64 ray threads"), std::string::npos) << note;
  EXPECT_NE(note.find("run 2 or more slaves on this machine"), std::string::npos) << note;
  EXPECT_NE(RayThreadsCapNote(200).find("run 4 or more slaves"), std::string::npos);
}

}  // namespace
}  // namespace raystack::master
