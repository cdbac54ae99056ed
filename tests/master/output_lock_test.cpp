// Each job locks its frames of an output (byte ranges of one lock file): jobs on other frames
// run side by side, and one ending (it widens its lock to the whole file, then removes the
// file) never refuses one starting on other frames (found by the day's second review: the
// starting job saw the whole-file lock and gave up).

#include "master/output_lock.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <thread>

#include "common/base/file_lock.h"
#include "common/base/temp_dir.h"

namespace raystack::testing {
namespace {

TEST(OutputLock, FramesOfOneOutputLockApartAndOverlapsAreRefused) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  const std::string out = dir->File("seq.exr");
  {
    Expected<master::OutputLock> a = master::OutputLock::Take(out, 0, 2);
    ASSERT_TRUE(a.ok()) << a.status().message();
    Expected<master::OutputLock> b = master::OutputLock::Take(out, 2, 4);
    ASSERT_TRUE(b.ok()) << b.status().message();
    Expected<master::OutputLock> c = master::OutputLock::Take(out, 3, 4);
    ASSERT_FALSE(c.ok());
    EXPECT_NE(c.status().message().find("for frame 3); wait for it, or give another --output or "
                                        "other --frames"), std::string::npos)
        << c.status().message();
    EXPECT_TRUE(std::filesystem::exists(dir->File(".seq.exr.lock")));
  }
  EXPECT_FALSE(std::filesystem::exists(dir->File(".seq.exr.lock"))) << "the last one removes it";
}

// A job writing through a symbolic link and one writing its target are one output (the day's
// second review: both exited 0, writing the same file).
TEST(OutputLock, ALinkAndItsTargetAreOneOutput) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  std::filesystem::create_directories(dir->File("real"));
  std::filesystem::create_symlink("real/img.exr", dir->File("link.exr"));
  Expected<master::OutputLock> a = master::OutputLock::Take(dir->File("real/img.exr"), 0, 1);
  ASSERT_TRUE(a.ok()) << a.status().message();
  EXPECT_FALSE(master::OutputLock::Take(dir->File("link.exr"), 0, 1).ok());
}

// An open descriptor of `path` (created) holding a lock on the whole file, as a job ending (it
// widens its lock before it removes the file) or an older build's job does; -1 on failure.
int HoldWholeFile(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd >= 0 && !TryLockWholeFile(fd)) {
    ::close(fd);
    return -1;
  }
  return fd;
}

TEST(OutputLock, AJobEndingDoesNotRefuseOneStartingOnOtherFrames) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  const std::string path = dir->File(".seq.exr.lock");
  // A job ending: it holds the whole file (widened), then removes it and lets go.
  const int ending = HoldWholeFile(path);
  ASSERT_GE(ending, 0);
  std::thread end([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(3));
    std::filesystem::remove(path);
    ::close(ending);
  });
  Expected<master::OutputLock> starting = master::OutputLock::Take(dir->File("seq.exr"), 2, 4);
  end.join();
  EXPECT_TRUE(starting.ok()) << starting.status().message();
}

// A whole-file lock that stays (an older build's job on the output) still refuses, after the
// short waits.
TEST(OutputLock, AWholeFileLockThatStaysRefuses) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  const std::string path = dir->File(".seq.exr.lock");
  const int older = HoldWholeFile(path);
  ASSERT_GE(older, 0);
  Expected<master::OutputLock> starting = master::OutputLock::Take(dir->File("seq.exr"), 2, 4);
  EXPECT_FALSE(starting.ok());
  ::close(older);
}

}  // namespace
}  // namespace raystack::testing
