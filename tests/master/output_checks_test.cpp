// Output trouble is found before rendering starts: a disk without room for the images (a real
// 256 KB tmpfs, mounted by the test: root only, as in CI) is an error naming the output path
// and the room, and nothing is rendered; so is an output that is a folder or not an EXR.

#include <gtest/gtest.h>
#include <sys/mount.h>
#include <unistd.h>

#include <sys/stat.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "common/base/memory_available.h"
#include "tests/prep/run_process.h"
#include "tests/support/store_dir_fixture.h"

namespace raystack::testing {
namespace {

using prep::testing::ProcessResult;
using prep::testing::RunProcess;

TEST(OutputChecks, AFullDiskIsReportedBeforeRendering) {
  if (geteuid() != 0) GTEST_SKIP() << "mounting a small tmpfs needs root (CI runs as root)";
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  const std::string small = dir->File("small");
  ASSERT_EQ(mkdir(small.c_str(), 0755), 0);
  if (mount("tmpfs", small.c_str(), "tmpfs", 0, "size=256k") != 0)
    GTEST_SKIP() << "cannot mount a tmpfs here: " << std::strerror(errno);
  std::ofstream(dir->File("scene.json")) << R"({ "store": "no-such-store",
    "camera": { "position": [0, 5, 10], "look_at": [0, 0, 0], "width": 400, "height": 300 } })";
  const ProcessResult r =
      RunProcess({kRaystackBinary, "render", dir->File("scene.json"), "--output",
                  small + "/out.exr", "-q"},
                 dir->path());
  umount(small.c_str());
  EXPECT_EQ(r.exit_code, 1);
  // Found before the store is even opened (it does not exist).
  EXPECT_NE(r.err.find(small + "/out.exr: the disk holding it has 0.3 MB free, the images need "
                       "up to 6.7 MB"), std::string::npos) << r.err;
}

// The output names the EXR (its extension gives way to .exr and .png): a folder or another
// extension is refused before anything is read, and an .EXR in capitals is an EXR.
TEST(OutputChecks, AFolderOrAnotherExtensionIsRefused) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  std::ofstream(dir->File("scene.json")) << R"({ "store": "no-such-store",
    "camera": { "position": [0, 5, 10], "look_at": [0, 0, 0], "width": 40, "height": 30 } })";
  ASSERT_EQ(mkdir(dir->File("images").c_str(), 0755), 0);
  ASSERT_EQ(mkdir(dir->File("png.png").c_str(), 0755), 0);
  for (const auto& [output, expected] : std::vector<std::pair<std::string, std::string>>{
           {dir->File("images"), "images: is a folder"},
           {dir->File("images") + "/", "images/: is a folder"},
           {dir->File("images/out.tar"), "out.tar: the output is an OpenEXR image"},
           {dir->File("png"), "png.png: cannot write: it is a folder"},  // where the PNG goes
           {dir->File("images/out.EXR"), "no-such-store"}}) {
    const ProcessResult r = RunProcess(
        {kRaystackBinary, "render", dir->File("scene.json"), "--output", output, "-q"}, dir->path());
    EXPECT_EQ(r.exit_code, 1) << output;
    EXPECT_NE(r.err.find(expected), std::string::npos) << output << ": " << r.err;
  }
  const ProcessResult empty =
      RunProcess({kRaystackBinary, "render", dir->File("scene.json"), "--output", ""}, dir->path());
  EXPECT_EQ(empty.exit_code, 2) << empty.err;  // not taken as "no --output"
}

// A frame whose film cannot fit in the memory available is refused before anything is read
// (running out midway ended in an uncaught std::bad_alloc), naming the camera and the sizes.
TEST(OutputChecks, AnImageLargerThanTheMemoryIsRefusedBeforeRendering) {
  const std::optional<uint64_t> available = MemoryAvailable();
  if (!available) GTEST_SKIP() << "no MemAvailable here";
  // 16384 x 16384, the largest a scene allows, needs ~56 GB.
  if (*available > uint64_t{16384} * 16384 * 200) GTEST_SKIP() << "this machine has room for it";
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  std::ofstream(dir->File("scene.json")) << R"({ "store": "no-such-store", "cameras": [
    { "position": [0, 5, 10], "look_at": [0, 0, 0], "width": 40, "height": 30 },
    { "position": [0, 5, 10], "look_at": [0, 0, 0], "width": 16384, "height": 16384 } ] })";
  const ProcessResult r = RunProcess(
      {kRaystackBinary, "render", dir->File("scene.json"), "--output", dir->File("out.exr"), "-q"},
      dir->path());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("camera 1: a 16384x16384 image needs about"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("GB is available here"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace raystack::testing
