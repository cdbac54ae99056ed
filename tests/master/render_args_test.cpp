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

}  // namespace
}  // namespace raystack::master
