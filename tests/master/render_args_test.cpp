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
// without a word. It is said now (by each process that renders), with what to do; slaves that
// share a machine are counted together.
TEST(RenderArgs, CoresBeyondWhatTheSlavesRunAreSaid) {
  EXPECT_EQ(RayThreadsCapNote(2, 2, 1), "");
  EXPECT_EQ(RayThreadsCapNote(64, 64, 1), "");
  std::string note = RayThreadsCapNote(128, 128, 1);
  EXPECT_NE(note.find("may use 128 cores and renders with 64 ray threads"), std::string::npos) << note;
  EXPECT_NE(note.find("run 2 or more slaves"), std::string::npos) << note;
  EXPECT_NE(RayThreadsCapNote(200, 200, 1).find("run 4 or more slaves"), std::string::npos);
  // Two unbound slaves on 128 cores use them all; on 256 they do not.
  EXPECT_EQ(RayThreadsCapNote(128, 128, 2), "");
  note = RayThreadsCapNote(256, 256, 2);
  EXPECT_NE(note.find("the 2 slaves on this machine may each use all of its 256 cores"),
            std::string::npos) << note;
  EXPECT_NE(note.find("run 4 or more slaves on it"), std::string::npos) << note;
  // Two slaves bound to 128 cores each of 256: each is told of its own share.
  note = RayThreadsCapNote(128, 256, 2);
  EXPECT_NE(note.find("may use 128 cores"), std::string::npos) << note;
  EXPECT_NE(note.find("run 4 or more slaves for these cores"), std::string::npos) << note;
}

}  // namespace
}  // namespace raystack::master
