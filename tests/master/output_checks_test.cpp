// Output trouble is found before rendering starts: a disk without room for the images (a real
// 256 KB tmpfs, mounted by the test: root only, as in CI) is an error naming the output path
// and the room, and nothing is rendered; so is an output that is a folder or not an EXR.

#include <gtest/gtest.h>

#include <sys/resource.h>
#include <sys/mount.h>
#include <sys/wait.h>
#include <unistd.h>

#include <sys/stat.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "common/base/memory_available.h"
#include "common/base/output_file.h"
#include "common/base/log.h"
#include "common/store/store_reader.h"
#include "master/preflight.h"
#include "tests/prep/run_process.h"
#include "tests/support/small_tmpfs.h"
#include "tests/support/store_dir_fixture.h"

namespace raystack::testing {
namespace {

using prep::testing::ProcessResult;
using prep::testing::RunProcess;

TEST(OutputChecks, AFullDiskIsReportedBeforeRendering) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  const SmallTmpfs tmpfs(dir->File("small"), "size=256k");
  if (tmpfs.path.empty()) GTEST_SKIP() << tmpfs.why;
  const std::string& small = tmpfs.path;
  std::ofstream(dir->File("scene.json")) << R"({ "store": "no-such-store",
    "camera": { "position": [0, 5, 10], "look_at": [0, 0, 0], "width": 400, "height": 300 } })";
  const ProcessResult r =
      RunProcess({kRaystackBinary, "render", dir->File("scene.json"), "--output",
                  small + "/out.exr", "-q"},
                 dir->path());
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
           {dir->File("images/.exr"), "images/.exr: the output needs a name before .exr"},
           {dir->File("png"), "png.png: cannot write: it is a folder"},  // where the PNG goes
           {dir->File("images/out.EXR"), "no-such-store"}}) {
    const ProcessResult r = RunProcess(
        {kRaystackBinary, "render", dir->File("scene.json"), "--output", output, "-q"}, dir->path());
    EXPECT_EQ(r.exit_code, 1) << output;
    EXPECT_NE(r.err.find(expected), std::string::npos) << output << ": " << r.err;
  }
  // With several cameras only out-0.exr, out-1.exr, ... are written: a folder named like the
  // output is in no one's way, but a path ending in '/' is still a folder.
  std::ofstream(dir->File("two.json")) << R"({ "store": "no-such-store", "cameras": [
    { "position": [0, 5, 10], "look_at": [0, 0, 0], "width": 40, "height": 30 },
    { "position": [0, 5, 10], "look_at": [0, 0, 0], "width": 40, "height": 30 } ] })";
  ASSERT_EQ(mkdir(dir->File("L.exr").c_str(), 0755), 0);
  for (const auto& [output, expected] : std::vector<std::pair<std::string, std::string>>{
           {dir->File("L.exr"), "no-such-store"},
           {dir->File("images") + "/", "images/: is a folder"}}) {
    const ProcessResult r = RunProcess(
        {kRaystackBinary, "render", dir->File("two.json"), "--output", output, "-q"}, dir->path());
    EXPECT_EQ(r.exit_code, 1) << output;
    EXPECT_NE(r.err.find(expected), std::string::npos) << output << ": " << r.err;
  }
  const ProcessResult empty =
      RunProcess({kRaystackBinary, "render", dir->File("scene.json"), "--output", ""}, dir->path());
  EXPECT_EQ(empty.exit_code, 2) << empty.err;  // not taken as "no --output"
}

// Each frame's file from the output path: the extension as the user spelled it for the EXR,
// -N before it with several cameras, and the PNG beside it.
TEST(OutputChecks, FramePathsKeepTheUsersName) {
  using master::FramePath;
  EXPECT_EQ(FramePath("out.exr", 0, 1, ".exr"), "out.exr");
  EXPECT_EQ(FramePath("UP.EXR", 0, 1, ".exr"), "UP.EXR");
  EXPECT_EQ(FramePath("UP.EXR", 0, 1, ".png"), "UP.png");
  EXPECT_EQ(FramePath("a.b/out.Exr", 1, 2, ".exr"), "a.b/out-1.Exr");
  EXPECT_EQ(FramePath("a.b/out", 1, 2, ".png"), "a.b/out-1.png");
  EXPECT_EQ(FramePath("ref.exr", 0, 3, ".exr"), "ref-0.exr");
}

// Found by an animator: frame-10.png sorted before frame-2.png (ls, globs, ffmpeg's glob), and
// a compositor's pattern (f.####.exr, f.%04d.exr) was taken literally (f.####-0.exr).
TEST(OutputChecks, FramePathsSortInFrameOrderAndFollowASequencePattern) {
  using master::FramePath;
  EXPECT_EQ(FramePath("f.exr", 2, 10, ".exr"), "f-2.exr");
  EXPECT_EQ(FramePath("f.exr", 2, 11, ".exr"), "f-02.exr");
  EXPECT_EQ(FramePath("f.exr", 10, 11, ".png"), "f-10.png");
  EXPECT_EQ(FramePath("f.exr", 7, 1000, ".exr"), "f-007.exr");
  EXPECT_EQ(FramePath("out/f.####.exr", 7, 24, ".exr"), "out/f.0007.exr");
  EXPECT_EQ(FramePath("out/f.####.exr", 7, 24, ".png"), "out/f.0007.png");
  EXPECT_EQ(FramePath("f_##.exr", 123, 200, ".exr"), "f_123.exr");  // more digits than asked
  EXPECT_EQ(FramePath("f.%04d.exr", 7, 24, ".exr"), "f.0007.exr");
  EXPECT_EQ(FramePath("f.%d.exr", 7, 24, ".exr"), "f.7.exr");
  EXPECT_EQ(FramePath("take#2.exr", 0, 1, ".exr"), "take#2.exr");  // one camera: as given
  EXPECT_EQ(FramePath("a#b/f.exr", 1, 2, ".exr"), "a#b/f-1.exr");  // a folder's '#' is its name
  EXPECT_EQ(FramePath("100%.exr", 1, 2, ".exr"), "100%-1.exr");
  EXPECT_EQ(FramePath("f%5d.exr", 1, 2, ".exr"), "f%5d-1.exr");  // space-padded: not ours
  EXPECT_EQ(FramePath("f%099999999999999999999999d.exr", 1, 2, ".exr"), "f000000000001.exr");
}

// -q leaves warnings and errors only: the line about a killed run's temporary removed goes
// with the progress lines (the temporary is removed all the same).
TEST(OutputChecks, QuietKeepsOnlyWarningsAndErrors) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  std::ofstream(dir->File("scene.json")) << R"({ "store": "no-such-store",
    "camera": { "position": [0, 5, 10], "look_at": [0, 0, 0], "width": 40, "height": 30 } })";
  const std::string out = dir->File("out.exr");
  std::string stale;  // a temporary of this machine's shape, of a process gone
  {
    Expected<AtomicOutput> output = AtomicOutput::Create(out);
    ASSERT_TRUE(output.ok());
    stale = output->temp_path();
  }
  const pid_t child = fork();
  if (child == 0) _exit(0);
  ASSERT_GT(child, 0);
  ASSERT_EQ(waitpid(child, nullptr, 0), child);
  stale = stale.substr(0, stale.rfind('-', stale.rfind('-') - 1) + 1) + std::to_string(child) + "-0";
  for (const bool quiet : {true, false}) {
    std::ofstream(stale) << "bytes";
    std::vector<std::string> argv = {kRaystackBinary, "render", dir->File("scene.json"), "--output", out};
    if (quiet) argv.push_back("-q");
    const ProcessResult r = RunProcess(argv, dir->path());
    EXPECT_EQ(r.exit_code, 1);
    EXPECT_NE(r.err.find("no-such-store"), std::string::npos) << r.err;  // errors stay
    EXPECT_EQ(r.err.find("left by an interrupted run") == std::string::npos, quiet) << r.err;
    EXPECT_FALSE(std::ifstream(stale).good()) << stale;
  }
}

// A scene redirected into /dev/stdin from a file: its relative paths are the working
// folder's (they were resolved against /dev: "/dev/no-such-store/index.bin").
TEST(OutputChecks, ASceneOnStdinResolvesPathsInTheWorkingFolder) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  std::ofstream(dir->File("scene.json")) << R"({ "store": "no-such-store",
    "camera": { "position": [0, 5, 10], "look_at": [0, 0, 0], "width": 40, "height": 30 } })";
  const ProcessResult r = RunProcess(
      {"/bin/sh", "-c", "cd \"$1\" && exec \"$0\" render /dev/stdin -q < scene.json",
       kRaystackBinary, dir->path()},
      dir->path());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("/dev/stdin: store \"no-such-store\": no such folder"), std::string::npos)
      << r.err;
  EXPECT_EQ(r.err.find("/dev/no-such-store"), std::string::npos) << r.err;
}

// Found by a helper following the docs: a store never converted, a model file given as the
// store, or an empty folder all said "index.bin: cannot open: No such file or directory", and a
// bad output named neither the scene file nor its key. Each now says where and what to do.
TEST(OutputChecks, AStoreOrOutputThatCannotBeUsedIsNamedWithTheSceneKeyAndWhatToDo) {
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  std::ofstream(dir->File("model.ply")) << "ply\n";
  std::filesystem::create_directory(dir->File("empty"));
  struct Case {
    std::string store, output, extra, says;
  } cases[] = {
      {"never-converted", "o.exr", "", "scene.json: store \"" + dir->File("never-converted") +
                                           "\": no such folder (convert a model into it with "
                                           "raystack-prep MODEL -o "},
      {"model.ply", "o.exr", "", "is a file, not a block store"},
      {"empty", "o.exr", "", "holds no block store (no index.bin; convert a model into it"},
      {"empty", "o.png", "", "scene.json: output: " + dir->File("o.png") +
                                 ": the output is an OpenEXR image"},
      {"empty", "o.exr", "--output=x.png", "--output: x.png: the output is an OpenEXR image"},
  };
  for (const Case& c : cases) {
    std::ofstream(dir->File("scene.json"))
        << R"({ "store": ")" << c.store << R"(", "output": ")" << c.output
        << R"(", "camera": { "position": [0, 5, 10], "look_at": [0, 0, 0], "width": 4, "height": 3 } })";
    std::vector<std::string> args = {kRaystackBinary, "render", dir->File("scene.json"), "-q"};
    if (!c.extra.empty()) {
      args.push_back("--output");
      args.push_back(c.extra.substr(9));
    }
    const ProcessResult r = RunProcess(args, dir->path());
    EXPECT_EQ(r.exit_code, 1) << c.store;
    EXPECT_NE(r.err.find(c.says), std::string::npos) << r.err;
  }
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
  EXPECT_NE(r.err.find("is available here (a smaller image would fit)"), std::string::npos) << r.err;
}

// Found by a scene author on a machine whose jobs run under an address-space limit (`ulimit -v`,
// as some schedulers set it): the check read only the machine's and the cgroups' memory, so a
// 3584 x 3584 frame started under 2 GB; it ran out midway, and with --time-limit the main thread's
// std::bad_alloc destroyed the running render thread: "terminate called without an active
// exception", exit 134, its lock left. The limit is now counted before rendering.
TEST(OutputChecks, AnImageLargerThanTheAddressSpaceLimitIsRefusedBeforeRendering) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "AddressSanitizer and ThreadSanitizer reserve terabytes of address space: they "
                  "cannot start under 2 GB";
#endif
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok());
  std::ofstream(dir->File("scene.json")) << R"({ "store": "no-such-store",
    "camera": { "position": [0, 5, 10], "look_at": [0, 0, 0], "width": 3584, "height": 3584 } })";
  const ProcessResult r = RunProcess(
      {kRaystackBinary, "render", dir->File("scene.json"), "--output", dir->File("out.exr"), "-q",
       "--time-limit", "3"},
      dir->path(), [] {
        const rlimit two_gb{uint64_t{2} << 30, uint64_t{2} << 30};
        if (setrlimit(RLIMIT_AS, &two_gb) != 0) _exit(125);
      });
  ASSERT_NE(r.exit_code, 125) << "cannot set RLIMIT_AS";
  EXPECT_EQ(r.signal, 0) << r.err;
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("camera 0: a 3584x3584 image needs about"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("is available under this process's address-space limit (ulimit -v"), std::string::npos)
      << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir->File(".out.exr.lock")));
}

// Found by the scale review: what every block costs beside its data (the index, the cache's and
// the loader's entries, a queue slot per ray thread; measured ~240 bytes and 3.3 per thread) was
// outside the slave's memory check, ~1.3 GB at 3 M blocks and 64 threads. Counted now, in every
// mode, and said.
class EngineMemory : public StoreDirFixture {};
TEST_F(EngineMemory, CountsEveryBlocksIndexBesideTheCache) {
  MakeStore("sphere:20000");
  Expected<std::unique_ptr<store::StoreReader>> store = store::StoreReader::Open(dir_->File("store"));
  ASSERT_TRUE(store.ok()) << store.status().message();
  const uint64_t blocks = (*store)->blocks().size();
  ASSERT_GT(blocks, 20u);
  slave::EngineOptions engine;
  engine.cache_bytes = 1 << 20;
  for (const int threads : {1, 64}) {
    engine.threads = threads;
    for (const slave::TraceMode mode : {slave::TraceMode::kStack, slave::TraceMode::kIncore}) {
      engine.mode = mode;
      const master::EngineMemory m = master::EngineMemoryOf(engine, **store);
      const uint64_t data = mode == slave::TraceMode::kStack
                                ? std::min<uint64_t>(engine.cache_bytes, (*store)->summary().raw_bytes)
                                : (*store)->summary().raw_bytes;
      EXPECT_GE(m.bytes, data + blocks * (240 + 3 * static_cast<uint64_t>(threads))) << threads;
      EXPECT_LE(m.bytes, data + blocks * (240 + 5 * static_cast<uint64_t>(threads))) << threads;
      EXPECT_NE(m.what.find(StrFormat(" and the index of its %llu blocks",
                                      static_cast<unsigned long long>(blocks))),
                std::string::npos) << m.what;
      // A cache smaller than the index: no smaller --cache-mb would help, and it says what would.
      if (mode == slave::TraceMode::kStack && threads == 64) {
        engine.cache_bytes = 1000;
        const master::EngineMemory small = master::EngineMemoryOf(engine, **store);
        EXPECT_NE(small.advice.find("the index alone takes"), std::string::npos) << small.advice;
        EXPECT_NE(small.advice.find("--target-block-kb"), std::string::npos) << small.advice;
        engine.cache_bytes = 1 << 20;
      }
    }
  }
}

}  // namespace
}  // namespace raystack::testing
