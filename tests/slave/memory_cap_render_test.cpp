// `raystack render` inside a real cgroup-v1 memory cap smaller than its store: --direct-io
// auto sees the cap's room (not the machine's free memory), reads past the page cache, and
// renders the image a run without the cap renders.

#include <fcntl.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>

#include "common/base/temp_dir.h"
#include "common/image/exr_io.h"
#include "tests/prep/run_process.h"
#include "tests/support/memory_cgroup.h"
#include "tests/support/store_dir_fixture.h"

namespace raystack::testing {
namespace {

using prep::testing::ProcessResult;
using prep::testing::RunProcess;

// 4 M triangles make a blocks.bin of ~75 MB: more than the cap, which holds the renderer
// (~40 MB with a 2 MB block cache) but not the store beside it.
constexpr uint64_t kCapBytes = 64ull << 20;

bool DropFromPageCache(const std::string& file) {
  const int fd = open(file.c_str(), O_RDONLY);
  if (fd < 0) return false;
  const bool ok = fsync(fd) == 0 && posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED) == 0;
  close(fd);
  return ok;
}

TEST(MemoryCapRender, AutoReadsDirectUnderACapSmallerThanTheStore) {
  std::string why;
  const std::unique_ptr<MemoryCgroup> group = MemoryCgroup::CreateOwnChild("raystack-render-cap", &why);
  if (!group) GTEST_SKIP() << "no cgroup-v1 memory cap possible: " << why;
  ASSERT_TRUE(group->Limit(kCapBytes)) << "cannot set the limit of " << group->path();

  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  const ProcessResult prep = RunProcess(
      {prep::testing::kPrepBinary, "--generate", "spheres:4000000", "-o", dir->File("store"), "-q"},
      dir->path());
  ASSERT_EQ(prep.exit_code, 0) << prep.err;
  ASSERT_GT(std::filesystem::file_size(dir->File("store/blocks.bin")), kCapBytes);
  const std::string scene = dir->File("scene.json");
  std::ofstream(scene) << R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 96, "height": 64 },
      "lights": [ { "type": "point", "position": [3, 8, 4], "intensity": [100, 100, 100] } ] })";
  const auto render = [&](const std::string& output, const std::string& direct_io,
                          const std::function<void()>& before_exec) {
    return RunProcess({kRaystackBinary, "render", scene, "--cache-mb", "2", "--no-png",
                       "--direct-io", direct_io, "--output", dir->File(output)},
                      dir->path(), before_exec);
  };

  // A cold store, as a store larger than memory is: pages left in the page cache by the
  // conversion (charged to this test's group) would be read without charging the cap's.
  ASSERT_TRUE(DropFromPageCache(dir->File("store/blocks.bin")));
  const ProcessResult capped = render("capped.exr", "auto", group->Joiner());
  ASSERT_NE(capped.exit_code, 125) << "the child could not join " << group->path();
  EXPECT_EQ(capped.signal, 0) << "killed by signal " << capped.signal
                              << " (SIGKILL = the OOM killer): " << capped.err;
  ASSERT_EQ(capped.exit_code, 0) << capped.err;
  EXPECT_NE(capped.out.find("reads: direct (--direct-io auto"), std::string::npos) << capped.out;
  // Read buffered, the store's pages are charged to the group until it is full (peak usage =
  // the cap); read direct, only the renderer's own memory is (~37 MB here, with its 32 I/O
  // threads).
  const uint64_t peak = ReadValue(group->File("memory.max_usage_in_bytes"));
  std::printf("memory cap %llu MB: peak usage %.1f MB\n",
              static_cast<unsigned long long>(kCapBytes >> 20), static_cast<double>(peak) / 1048576.0);
  EXPECT_GT(peak, 0u) << "nothing was charged to the group: the run was not capped";
  EXPECT_LT(peak, kCapBytes / 8 * 7) << "the page cache filled the cap";

  const ProcessResult reference = render("reference.exr", "off", {});
  ASSERT_EQ(reference.exit_code, 0) << reference.err;
  Expected<image::ImageLayers> a = image::ReadExr(dir->File("reference.exr"));
  Expected<image::ImageLayers> b = image::ReadExr(dir->File("capped.exr"));
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_EQ(a->rgba.size(), b->rgba.size());
  EXPECT_EQ(0, std::memcmp(a->rgba.data(), b->rgba.data(), a->rgba.size() * sizeof(float)));
  EXPECT_EQ(0, std::memcmp(a->z.data(), b->z.data(), a->z.size() * sizeof(float)));
}

// Found by a user with a model too big for RAM: --mode bvh passed the memory check (which
// counted the blocks only) and was then killed by the kernel as it built its tree, without a
// word. The tree's peak is counted now: refused up front, naming it; incore still runs.
TEST(MemoryCapRender, ModeBvhCountsItsTreeBeforeItStarts) {
  std::string why;
  const std::unique_ptr<MemoryCgroup> group = MemoryCgroup::CreateOwnChild("raystack-bvh-cap", &why);
  if (!group) GTEST_SKIP() << "no cgroup-v1 memory cap possible: " << why;
  ASSERT_TRUE(group->Limit(kCapBytes)) << "cannot set the limit of " << group->path();
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  // ~12 MB of decoded blocks, whose tree would peak at ~72 MB (180 bytes a triangle).
  const ProcessResult prep = RunProcess(
      {prep::testing::kPrepBinary, "--generate", "spheres:400000", "-o", dir->File("store"), "-q"},
      dir->path());
  ASSERT_EQ(prep.exit_code, 0) << prep.err;
  const std::string scene = dir->File("scene.json");
  std::ofstream(scene) << R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 48, "height": 32 } })";
  const auto render = [&](const std::string& mode) {
    return RunProcess({kRaystackBinary, "render", scene, "--mode", mode, "--no-png", "-q",
                       "--output", dir->File(mode + ".exr")}, dir->path(), group->Joiner());
  };
  const ProcessResult bvh = render("bvh");
  ASSERT_NE(bvh.exit_code, 125) << "the child could not join " << group->path();
  EXPECT_EQ(bvh.signal, 0) << "killed by signal " << bvh.signal << ": " << bvh.err;
  EXPECT_EQ(bvh.exit_code, 1) << bvh.err;
  EXPECT_NE(bvh.err.find("the one BVH over every triangle (--mode bvh)"), std::string::npos) << bvh.err;
  EXPECT_NE(bvh.err.find("--mode stack keeps only --cache-mb of blocks"), std::string::npos) << bvh.err;
  const ProcessResult incore = render("incore");
  EXPECT_EQ(incore.signal, 0) << incore.err;
  EXPECT_EQ(incore.exit_code, 0) << incore.err;
}

}  // namespace
}  // namespace raystack::testing
