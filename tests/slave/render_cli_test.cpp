// `raystack render` run as a user runs it: a scene file in, an EXR with every layer, a PNG and
// JSON statistics out; bad input ends with a message naming what is wrong and a non-zero exit.

#include <gtest/gtest.h>

#include <sys/stat.h>

#include <sched.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "common/base/log.h"
#include "common/base/temp_dir.h"
#include "common/image/exr_io.h"
#include "tests/prep/run_process.h"
#include "tests/support/older_store.h"
#include "tests/support/store_dir_fixture.h"

namespace raystack::testing {
namespace {

using prep::testing::kPrepBinary;
using prep::testing::ProcessResult;
using prep::testing::RunProcess;
using prep::testing::Slurp;

const std::string& kRaystack = kRaystackBinary;

class RenderCli : public StoreDirFixture {
 protected:
  void SetUp() override { MakeStore("spheres:20000"); }

  std::string WriteScene(const std::string& body) {
    const std::string path = dir_->File("scene.json");
    std::ofstream(path) << body;
    return path;
  }

  // The spheres path traced at `spp` samples a pixel (64 x 40 unless given).
  std::string PathScene(int spp, int width = 64, int height = 40) {
    return WriteScene(StrFormat(R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": %d, "height": %d },
      "lights": [ { "type": "point", "position": [3, 8, 4], "intensity": [100, 100, 100] } ],
      "integrator": { "type": "path", "max_depth": 3, "spp": %d, "seed": 5 },
      "output": "out.exr" })", width, height, spp));
  }

  std::string Scene(const std::string& extra = "") {
    return WriteScene(R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 64, "height": 40 },
      "lights": [ { "type": "point", "position": [3, 8, 4], "intensity": [100, 100, 100] } ],
      "integrator": { "type": "whitted", "max_depth": 3, "spp": 1, "seed": 1 },
      "output": "out.exr")" + extra + " }");
  }
};

TEST_F(RenderCli, WritesEveryLayerAPngAndStatistics) {
  const ProcessResult r = RunProcess(
      {kRaystack, "render", Scene(), "--cache-mb", "1", "--threads", "2", "--stats",
       dir_->File("stats.json"), "-q"},
      dir_->path());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  Expected<image::ImageLayers> image = image::ReadExr(dir_->File("out.exr"));
  ASSERT_TRUE(image.ok()) << image.status().message();
  EXPECT_EQ(image->width, 64);
  EXPECT_EQ(image->height, 40);
  EXPECT_EQ(image->z.size(), 64u * 40u);
  EXPECT_EQ(image->normal.size(), 3u * 64u * 40u);
  EXPECT_EQ(image->albedo.size(), 3u * 64u * 40u);
  EXPECT_EQ(image->variance.size(), 64u * 40u);
  ASSERT_EQ(image->samples.size(), 64u * 40u);
  for (uint32_t n : image->samples) EXPECT_EQ(n, 1u);
  int misses = 0;
  for (float z : image->z) misses += std::isinf(z) ? 1 : 0;
  EXPECT_GT(misses, 0);
  EXPECT_LT(misses, 64 * 40);
  EXPECT_FALSE(Slurp(dir_->File("out.png")).empty());
  const std::string stats = Slurp(dir_->File("stats.json"));
  for (const char* key : {"\"rays_per_second\"", "\"blocks_loaded\"", "\"blocks_distinct\"",
                          "\"cache_hit_rate\"", "\"loader_busy_seconds\"", "\"peak_stack_bytes\"",
                          "\"peak_rss_bytes\"", "\"bytes_read\"", "\"shadow\""})
    EXPECT_NE(stats.find(key), std::string::npos) << key;
}

// Emitters that will not light as a user may think are said up front (found by a helper playing
// a lighting artist: the Cornell box under whitted came out black but for its lamp, silently):
// whitted lights with point lights only; path tracing without lights.bin (an older store) finds
// the emitters only where rays meet them.
TEST_F(RenderCli, EmittersThatWillNotLightAsExpectedAreAWarning) {
  const ProcessResult prep = RunProcess(
      {kPrepBinary, std::string(RAYSTACK_TEST_DATA) + "/CornellBox-Original.obj", "-o",
       dir_->File("box"), "-q"},
      dir_->path());
  ASSERT_EQ(prep.exit_code, 0) << prep.err;
  ASSERT_TRUE(CopyAsOlderStore(dir_->File("box"), dir_->File("older")));
  const auto render = [&](const std::string& store, const std::string& integrator) {
    const std::string path = dir_->File("box.json");
    std::ofstream(path) << R"({ "store": ")" << store << R"(",
      "camera": { "position": [0, 1, 3.2], "look_at": [0, 1, 0], "width": 16, "height": 16 },
      "integrator": { "type": ")" << integrator << R"(", "max_depth": 2, "spp": 2 },
      "output": "box.exr" })";
    return RunProcess({kRaystack, "render", path, "--no-png", "-q"}, dir_->path());
  };
  const std::string whitted = "lights with point lights only";
  const std::string older = "converted before raystack-prep listed emitters";
  ProcessResult r = render("box", "whitted");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find(whitted), std::string::npos) << r.err;
  r = render("older", "path");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find(older), std::string::npos) << r.err;
  r = render("box", "path");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find(older), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find(whitted), std::string::npos) << r.err;
}

// Found by a scene author: under whitted a white background took the place of a light for the
// "no light" warning, and the model came out black without a word (whitted lights with point
// lights only; the background lights under path only).
TEST_F(RenderCli, AWhittedSceneLitByItsBackgroundAloneIsAWarning) {
  const auto render = [&](const std::string& integrator, const std::string& lights) {
    const std::string path = WriteScene(R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 16, "height": 12 },
      "background": [1, 1, 1], "lights": )" + lights + R"(,
      "integrator": { "type": ")" + integrator + R"(", "max_depth": 2, "spp": 1 } })");
    return RunProcess({kRaystack, "render", path, "--no-png", "-q", "--output", dir_->File("bg.exr")},
                      dir_->path());
  };
  const std::string warning = "the whitted integrator lights with point lights only, and the scene "
                              "has none: every diffuse surface will be black (the background is seen";
  ProcessResult r = render("whitted", "[]");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find(warning), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("the scene has no light"), std::string::npos) << r.err;
  for (const auto& [integrator, lights] : std::vector<std::pair<std::string, std::string>>{
           {"path", "[]"},
           {"whitted", R"([ { "type": "point", "position": [3, 8, 4], "intensity": [9, 9, 9] } ])"}}) {
    r = render(integrator, lights);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(r.err.find("point lights only"), std::string::npos) << integrator << ": " << r.err;
  }
}

// Path tracing aims one shadow ray at one light, chosen mostly by power (found by a scene
// author: the README said so, the code chose uniformly, and ten negligible fill lights beside the
// one that lit the scene took ten elevenths of its shadow rays, each then weighed 11 times: +31%
// of variance). Nine choices in ten by power: the fill lights change the image by a fraction of
// what they did.
TEST_F(RenderCli, NegligibleFillLightsBarelyChangeAPathTracedImage) {
  const auto render = [&](const std::string& name, int fill_lights) {
    std::string lights = R"([ { "type": "point", "position": [3, 8, 4], "intensity": [100, 100, 100] })";
    for (int i = 0; i < fill_lights; ++i)
      lights += StrFormat(R"(, { "type": "point", "position": [%d, 6, -3], "intensity": [1e-5, 1e-5, 1e-5] })", i - 5);
    const std::string path = WriteScene(R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 48, "height": 32 },
      "lights": )" + lights + R"( ],
      "integrator": { "type": "path", "max_depth": 3, "spp": 2, "seed": 5 } })");
    const ProcessResult r = RunProcess({kRaystack, "render", path, "--no-png", "-q", "--output",
                                        dir_->File(name)}, dir_->path());
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return image::ReadExr(dir_->File(name));
  };
  const Expected<image::ImageLayers> one = render("one.exr", 0), eleven = render("eleven.exr", 10);
  ASSERT_TRUE(one.ok() && eleven.ok());
  double difference = 0, sum = 0;
  for (size_t i = 0; i < one->rgba.size(); ++i) {
    if (i % 4 == 3) continue;  // alpha
    difference += std::fabs(double{one->rgba[i]} - double{eleven->rgba[i]});
    sum += std::fabs(double{one->rgba[i]});
  }
  ASSERT_GT(sum, 0);
  // Uniformly chosen: 1.6 times the image's mean.
  EXPECT_LT(difference / sum, 0.5);
}

// The mean of a path-traced image over two lights is the sum of their images' means: every light
// is chosen with a chance it is weighed by. Found by the day's review: by power alone, with 24
// random bits, a lamp of 10 beside a sun of 1e9 (a 1e-8 share of the power) was never chosen,
// and its 4% of the image was missing.
TEST_F(RenderCli, EachLightAddsItsOwnImage) {
  const auto mean = [&](const std::string& name, const std::string& lights) {
    const std::string path = WriteScene(R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 48, "height": 32 },
      "lights": [ )" + lights + R"( ],
      "integrator": { "type": "path", "max_depth": 1, "spp": 4, "seed": 3 } })");
    const ProcessResult r = RunProcess({kRaystack, "render", path, "--no-png", "-q", "--output",
                                        dir_->File(name)}, dir_->path());
    EXPECT_EQ(r.exit_code, 0) << r.err;
    const Expected<image::ImageLayers> image = image::ReadExr(dir_->File(name));
    double sum = 0;
    if (image.ok())
      for (size_t i = 0; i < image->rgba.size(); ++i) sum += i % 4 == 3 ? 0.0 : double{image->rgba[i]};
    return image.ok() ? sum / static_cast<double>(image->pixel_count()) : -1.0;
  };
  const std::string lamp = R"({ "type": "point", "position": [1, 3, 1], "intensity": [10, 10, 10] })";
  const std::string sun = R"({ "type": "point", "position": [4000, 5000, 2000], "intensity": [1e9, 1e9, 1e9] })";
  const double a = mean("lamp.exr", lamp), b = mean("sun.exr", sun), both = mean("both.exr", sun + ", " + lamp);
  ASSERT_GT(a, 0);
  ASSERT_GT(b, 0);
  EXPECT_GT(a, 0.02 * (a + b)) << "the lamp should matter for the test to mean anything";
  EXPECT_NEAR(both, a + b, 0.01 * (a + b)) << "lamp " << a << ", sun " << b;
}

// The default --threads is the cores this process may use (found by an operator: mpirun binds a
// rank to one core when it starts two or fewer, and the rank still ran a ray thread per core of
// the machine, time-sharing that core: 0.6-0.7x the speed). Bound to one CPU, as taskset does.
TEST_F(RenderCli, TheDefaultThreadsAreTheCoresThisProcessMayUse) {
  const ProcessResult r = RunProcess(
      {kRaystack, "render", Scene(), "--no-png", "--output", dir_->File("bound.exr")}, dir_->path(),
      [] {
        cpu_set_t one;
        CPU_ZERO(&one);
        CPU_SET(0, &one);
        if (sched_setaffinity(0, sizeof one, &one) != 0) _exit(125);
      });
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("stack mode, 1 thread:"), std::string::npos) << r.out;
}

// A number of the statistics JSON ("key": value), NaN when missing.
double StatOf(const std::string& json, const std::string& key) {
  const size_t at = json.find("\"" + key + "\": ");
  return at == std::string::npos ? std::nan("") : std::strtod(json.c_str() + at + key.size() + 4, nullptr);
}

// Found by a researcher: in sync mode the time the ray threads spent in their own reads counted
// as busy (ray_idle_seconds and loader_busy_seconds 0 with 1 ms injected per read), so its I/O
// wait and T_io could not be read from the figures; in core the budget read 2^64 - 1.
TEST_F(RenderCli, SyncModeCountsItsReadsAsWaiting) {
  const ProcessResult r = RunProcess({kRaystack, "render", Scene(), "--mode", "sync", "--cache-mb",
                                      "1", "--io-latency-us", "2000", "--threads", "2", "--no-png",
                                      "-q", "--output", dir_->File("sync.exr"), "--stats",
                                      dir_->File("sync.json")},
                                     dir_->path());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string json = Slurp(dir_->File("sync.json"));
  const double reads = StatOf(json, "reads");
  ASSERT_GT(reads, 0) << json;
  // Each read sleeps 2 ms at least: that much waiting, and as much loading.
  EXPECT_GE(StatOf(json, "ray_idle_seconds"), reads * 0.002) << json;
  EXPECT_GE(StatOf(json, "loader_busy_seconds"), reads * 0.002) << json;
  const ProcessResult incore = RunProcess({kRaystack, "render", Scene(), "--mode", "incore", "-q",
                                           "--no-png", "--output", dir_->File("incore.exr"),
                                           "--stats", dir_->File("incore.json")},
                                          dir_->path());
  ASSERT_EQ(incore.exit_code, 0) << incore.err;
  EXPECT_NE(Slurp(dir_->File("incore.json")).find("\"cache_budget_bytes\": null"), std::string::npos);
}

// --help says where the installed documents are, wherever raystack was installed (found by an
// operator: installed under /opt/raystack it named /usr/share/doc/raystack/).
TEST_F(RenderCli, HelpNamesTheDocumentsBesideTheInstalledProgram) {
  const std::string prefix = dir_->File("opt raystack");
  std::filesystem::create_directories(prefix + "/bin");
  std::filesystem::create_directories(prefix + "/share/doc/raystack");
  std::filesystem::copy_file(kRaystack, prefix + "/bin/raystack");
  std::filesystem::permissions(prefix + "/bin/raystack", std::filesystem::perms::owner_all);
  const ProcessResult r = RunProcess({prefix + "/bin/raystack", "render", "--help"}, dir_->path());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find(prefix + "/share/doc/raystack/"), std::string::npos) << r.out;
}

// Found by the day's review: under a limit on threads (ulimit -u) or address space (-v), a
// thread that could not start threw std::system_error out of a thread (std::terminate: exit 134,
// the output's lock left). At every limit the render now ends with a message, or finishes with
// fewer I/O threads. The limit counts a user's threads, which root's are not held to: the
// render runs as nobody.
TEST_F(RenderCli, ALimitOnThreadsEndsWithAMessageNeverAnAbort) {
  if (geteuid() != 0) GTEST_SKIP() << "running as another user needs root (CI runs as root)";
  std::filesystem::permissions(dir_->path(), std::filesystem::perms::all);
  for (const auto& entry : std::filesystem::recursive_directory_iterator(dir_->path()))
    std::filesystem::permissions(entry.path(), std::filesystem::perms::all);
  const std::string scene = Scene();
  int finished = 0;
  for (const rlim_t threads : {1, 2, 3, 4, 5, 6, 8, 12, 64}) {
    const std::string out = dir_->File("limited-" + std::to_string(threads) + ".exr");
    const ProcessResult r = RunProcess(
        {kRaystack, "render", scene, "--threads", "2", "--cache-mb", "1", "--no-png", "-q",
         "--output", out},
        dir_->path(), [threads] {
          const rlimit limit{threads, threads};
          if (setgid(65534) != 0 || setuid(65534) != 0 || setrlimit(RLIMIT_NPROC, &limit) != 0)
            _exit(125);
        });
    ASSERT_NE(r.exit_code, 125) << "cannot become nobody with a limit of " << threads;
    EXPECT_EQ(r.signal, 0) << threads << " threads: " << r.err;
    if (r.exit_code == 0) {
      ++finished;
      continue;
    }
    EXPECT_EQ(r.exit_code, 1) << threads << " threads: " << r.err;
    EXPECT_NE(r.err.find("a limit on threads or address space"), std::string::npos)
        << threads << " threads: " << r.err;
  }
  EXPECT_GT(finished, 0) << "no limit let the render finish";
}

// The same under an address-space limit (ulimit -v), where any allocation of any thread may
// fail (found by the day's second review: a std::bad_alloc out of the loader's or an I/O
// thread, or thrown again by a handler building its message, was std::terminate in 3 runs of
// 6). From a limit the render cannot start under to one it finishes under: a message or the
// image, never a signal.
TEST_F(RenderCli, ALimitOnAddressSpaceEndsWithAMessageNeverAnAbort) {
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  GTEST_SKIP() << "AddressSanitizer and ThreadSanitizer reserve terabytes of address space: they "
                  "cannot start under one";
#endif
  const std::string scene = PathScene(4);
  int finished = 0;
  for (const rlim_t megabytes : {120, 150, 180, 200, 220, 240, 260, 280, 320, 400}) {
    const std::string out = dir_->File("limited-" + std::to_string(megabytes) + ".exr");
    const ProcessResult r = RunProcess(
        {kRaystack, "render", scene, "--threads", "8", "--cache-mb", "1", "--no-png", "-q",
         "--output", out},
        dir_->path(), [megabytes] {
          const rlimit limit{megabytes << 20, megabytes << 20};
          if (setrlimit(RLIMIT_AS, &limit) != 0) _exit(125);
        });
    ASSERT_NE(r.exit_code, 125) << "cannot set RLIMIT_AS";
    EXPECT_EQ(r.signal, 0) << megabytes << " MB: " << r.err;
    EXPECT_TRUE(r.exit_code == 0 || r.exit_code == 1) << megabytes << " MB: " << r.exit_code << " " << r.err;
    finished += r.exit_code == 0;
  }
  EXPECT_GT(finished, 0) << "no limit let the render finish";
}

TEST_F(RenderCli, ModesWriteTheSameImage) {
  std::vector<image::ImageLayers> images;
  for (const char* mode : {"stack", "sync", "incore", "bvh"}) {
    const ProcessResult r = RunProcess({kRaystack, "render", Scene(), "--mode", mode,
                                        "--cache-mb", "1", "-q", "--output",
                                        dir_->File(std::string(mode) + ".exr")},
                                       dir_->path());
    ASSERT_EQ(r.exit_code, 0) << r.err;
    Expected<image::ImageLayers> image = image::ReadExr(dir_->File(std::string(mode) + ".exr"));
    ASSERT_TRUE(image.ok());
    images.push_back(std::move(*image));
  }
  for (size_t i = 1; i < images.size(); ++i) {
    EXPECT_EQ(0, std::memcmp(images[i].rgba.data(), images[0].rgba.data(), images[0].rgba.size() * 4));
    EXPECT_EQ(0, std::memcmp(images[i].z.data(), images[0].z.data(), images[0].z.size() * 4));
  }
}

// The first pass's coarse rounds sweep the frame five times: with every block in the cache
// that is free, out of core it loads the frame's blocks again on each sweep. --coarse-rounds
// auto keeps them only when the decoded store fits the cache, and says which it chose.
TEST_F(RenderCli, CoarseRoundsOnlyWhenTheStoreFitsTheCache) {
  const std::string scene = WriteScene(R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 256, "height": 160 },
      "lights": [ { "type": "point", "position": [3, 8, 4], "intensity": [100, 100, 100] } ],
      "output": "out.exr" })");
  const auto loads = [&](const std::vector<std::string>& extra, std::string* out) {
    std::vector<std::string> args = {kRaystack, "render", scene, "--threads", "1", "--no-png",
                                     "--tile-size", "16", "--stats", dir_->File("s.json")};
    args.insert(args.end(), extra.begin(), extra.end());
    const ProcessResult r = RunProcess(args, dir_->path());
    EXPECT_EQ(r.exit_code, 0) << r.err;
    *out = r.out;
    const std::string stats = Slurp(dir_->File("s.json"));
    const size_t at = stats.find("\"blocks_loaded\": ");
    return at == std::string::npos ? -1L : std::stol(stats.substr(at + 17));
  };
  std::string out;
  // 0.25 MB holds a few of the store's blocks, not all of them.
  const long auto_small = loads({"--cache-mb", "0.25"}, &out);
  EXPECT_NE(out.find("first pass: one sweep (decoded blocks"), std::string::npos) << out;
  const long rounds_small = loads({"--cache-mb", "0.25", "--coarse-rounds", "on"}, &out);
  EXPECT_NE(out.find("first pass: 5 coarse rounds (--coarse-rounds on)"), std::string::npos) << out;
  ASSERT_GT(auto_small, 0);
  EXPECT_LT(auto_small * 3, rounds_small * 2) << "one sweep should load far fewer blocks";
  loads({"--cache-mb", "64"}, &out);
  EXPECT_NE(out.find("first pass: 5 coarse rounds (decoded blocks"), std::string::npos) << out;
  const ProcessResult bad = RunProcess({kRaystack, "render", scene, "--coarse-rounds", "maybe"},
                                       dir_->path());
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("--coarse-rounds must be auto, on or off"), std::string::npos) << bad.err;
}

// --direct-io: reads past the page cache give the same image, and the run says how it read
// (on the terminal and in the statistics). auto reads a store this small buffered.
TEST_F(RenderCli, DirectIoSaysHowItReadsAndKeepsTheImage) {
  std::vector<image::ImageLayers> images;
  for (const char* mode : {"off", "on", "auto"}) {
    SCOPED_TRACE(mode);
    const std::string out = dir_->File(std::string(mode) + ".exr");
    const ProcessResult r = RunProcess({kRaystack, "render", Scene(), "--direct-io", mode,
                                        "--cache-mb", "0.25", "--no-png", "--output", out,
                                        "--stats", dir_->File("s.json")},
                                       dir_->path());
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const bool direct = std::string(mode) == "on";
    EXPECT_NE(r.out.find(std::string("reads: ") + (direct ? "direct" : "buffered") +
                         " (--direct-io " + mode),
              std::string::npos)
        << r.out;
    EXPECT_NE(Slurp(dir_->File("s.json")).find(std::string("\"direct_reads\": ") +
                                                (direct ? "true" : "false")),
              std::string::npos);
    Expected<image::ImageLayers> image = image::ReadExr(out);
    ASSERT_TRUE(image.ok());
    images.push_back(std::move(*image));
  }
  for (size_t i = 1; i < images.size(); ++i) {
    EXPECT_EQ(0, std::memcmp(images[i].rgba.data(), images[0].rgba.data(), images[0].rgba.size() * 4));
    EXPECT_EQ(0, std::memcmp(images[i].z.data(), images[0].z.data(), images[0].z.size() * 4));
  }
  const ProcessResult bad = RunProcess({kRaystack, "render", Scene(), "--direct-io", "always"},
                                       dir_->path());
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("--direct-io must be auto, on or off"), std::string::npos) << bad.err;
}

// Found by a helper reading the docs: --blocks and the slaves' faults were taken in one process
// and did nothing, without a word; --fault-fail-read did nothing there either, though the one
// process reads its blocks itself. Now the first warns and the second fails the read.
TEST_F(RenderCli, SlaveOptionsWarnInOneProcessAndAnInjectedReadErrorFailsThere) {
  ProcessResult r = RunProcess({kRaystack, "render", Scene(), "--blocks", "loc", "--lost-after",
                                "5", "-q"}, dir_->path());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("--blocks has no effect in one process"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--lost-after has no effect in one process"), std::string::npos) << r.err;
  r = RunProcess({kRaystack, "render", Scene(), "--fault-fail-read", "0", "-q"}, dir_->path());
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("block"), std::string::npos) << r.err;
}

// Found by a user with a model too big for RAM: a block that could not be read mid-frame ended
// the job with no image at all, the frame's samples so far lost (Ctrl-C kept them). Now they
// are written as an interrupt writes them, the error says where, and --resume (the store
// repaired) ends with the image an uninterrupted run gives, bit for bit.
TEST_F(RenderCli, AReadFailingMidFrameKeepsTheFrameSoFarForResume) {
  const std::string scene = PathScene(16);
  // One pass of 16 samples: pixels finish tile by tile, so a third of the way some have all of
  // theirs (the loads of a run vary a little with timing: the fault comes well before the end).
  const std::vector<std::string> common = {kRaystack, "render", scene, "--cache-mb", "0.2",
                                           "--threads", "1", "--pass-spp", "16", "-q", "--no-png"};
  std::vector<std::string> whole = common;
  whole.insert(whole.end(), {"--output", dir_->File("whole.exr"), "--stats", dir_->File("stats.json")});
  ProcessResult r = RunProcess(whole, dir_->path());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string text = prep::testing::Slurp(dir_->File("stats.json"));
  const size_t at = text.find("\"blocks_loaded\": ");
  ASSERT_NE(at, std::string::npos) << text;
  const long loads = std::stol(text.substr(at + 17));
  ASSERT_GT(loads, 20) << "the cache must be too small to hold the frame's blocks";

  std::vector<std::string> failing = common;
  failing.insert(failing.end(), {"--fault-fail-read", std::to_string(loads / 3)});
  r = RunProcess(failing, dir_->path());
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("read failed (injected fault)"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("; the frame so far is in "), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("pixels with all their samples; once the cause is fixed, the same command "
                       "with --resume keeps those"), std::string::npos) << r.err;
  ASSERT_TRUE(std::filesystem::exists(dir_->File("out.exr"))) << r.err;

  std::vector<std::string> resumed = common;
  resumed.push_back("--resume");
  r = RunProcess(resumed, dir_->path());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  Expected<image::ImageLayers> a = image::ReadExr(dir_->File("whole.exr"));
  Expected<image::ImageLayers> b = image::ReadExr(dir_->File("out.exr"));
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_EQ(a->rgba.size(), b->rgba.size());
  EXPECT_EQ(0, std::memcmp(a->rgba.data(), b->rgba.data(), a->rgba.size() * sizeof(float)));
}

// Found by a render-farm operator: with progressive passes a checkpoint keeps nothing for
// --resume until the last pass, and nothing said so before an interrupted run's message. Now a
// warning at start gives the options that keep whole tiles as they finish.
TEST_F(RenderCli, CheckpointsThatWouldKeepLittleAreWarnedOfWithTheFix) {
  const std::string scene = PathScene(256, 16, 8);
  const auto run = [&](std::vector<std::string> extra) {
    std::vector<std::string> argv = {kRaystack, "render", scene, "--checkpoint-s", "60", "-q", "--no-png"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    return RunProcess(argv, dir_->path());
  };
  ProcessResult r = run({});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("progressive passes give it the last of them in the last pass"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--pass-spp 256 --tile-size 8 renders whole tiles"), std::string::npos) << r.err;
  r = run({"--pass-spp", "256"});  // one pass, but 32 x 32 tiles take their samples in sweeps
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("a tile this large takes them in several sweeps"), std::string::npos) << r.err;
  r = run({"--pass-spp", "256", "--tile-size", "8"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find("--checkpoint-s:"), std::string::npos) << r.err;
  // Past 1024 samples a pixel only tiles under 4 x 4 take them in one sweep, and those cost a
  // round trip each under mpirun: not advised, and the advice does not send the user in a
  // circle (a review found --tile-size 1 advised, then warned about again).
  r = run({"--spp", "4096", "--pass-spp", "4096", "--time-limit", "0.2"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find("--checkpoint-s:"), std::string::npos) << r.err;
  r = run({"--spp", "4096", "--time-limit", "0.2"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("--pass-spp 4096 keeps pixels as their tiles' last sweep ends"), std::string::npos)
      << r.err;
  EXPECT_EQ(r.err.find("--tile-size 1"), std::string::npos) << r.err;
}

// Found by a render-farm operator: a frame whose final write failed (a full disk, its folder
// removed) was lost at once, its render done; only an older checkpoint was left. It is the
// frame's only copy, so it is tried again (1, 2, 4 ... s apart, for minutes), saying so.
TEST_F(RenderCli, AFrameThatCannotBeWrittenIsTriedAgain) {
  const ProcessResult r = RunProcess({kRaystack, "render", Scene(), "--fault-fail-writes", "2",
                                      "--no-png", "-q"}, dir_->path());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("no space left on device (--fault-fail-writes); trying again every few "
                       "seconds"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("out.exr written after all"), std::string::npos) << r.err;
  Expected<image::ImageLayers> image = image::ReadExr(dir_->File("out.exr"));
  ASSERT_TRUE(image.ok()) << image.status().message();
  EXPECT_FALSE(image->partial);
}

// A --cache-mb far above the store's decoded blocks chose direct reads "because the page cache
// cannot keep the store" (a user's report): the cache never holds more than the store.
TEST_F(RenderCli, ACacheLargerThanTheStoreDoesNotChooseDirectReads) {
  const ProcessResult r = RunProcess({kRaystack, "render", Scene(), "--cache-mb", "1000000",
                                      "--no-png"}, dir_->path());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("reads: buffered (--direct-io auto: "), std::string::npos) << r.out;
}

// The sync mode's figures spoke of a loader it does not have ("0 by the loader itself, the rest
// by 0 I/O threads; loader busy 0.000 s"): they say who reads there.
TEST_F(RenderCli, SyncModeFiguresSayTheRayThreadsRead) {
  const ProcessResult r = RunProcess({kRaystack, "render", Scene(), "--mode", "sync", "--cache-mb",
                                      "1", "--no-png"}, dir_->path());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("reads (by the ray threads themselves, each waiting for its own)"),
            std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("loader"), std::string::npos) << r.out;
}

// Found by a hostile-input review: a convergence log whose writes failed (a full disk) ended
// the job with 0, its rows lost without a word; one a pipe with no reader held the job in
// open(), deaf to a first Ctrl-C. Now the first is said at once and ends the job with 1 after
// its image, the second is an error before anything starts.
TEST_F(RenderCli, AConvergenceLogThatCannotBeWrittenIsSaid) {
  ProcessResult r = RunProcess({kRaystack, "render", Scene(), "--convergence-log", "/dev/full",
                                "--log-interval", "0.01", "-q", "--no-png"}, dir_->path());
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("/dev/full: cannot write the convergence log: No space left on device"),
            std::string::npos) << r.err;
  EXPECT_TRUE(std::filesystem::exists(dir_->File("out.exr"))) << "the image is kept";
  const std::string fifo = dir_->File("log.fifo");
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  r = RunProcess({kRaystack, "render", Scene(), "--convergence-log", fifo, "-q", "--no-png",
                  "--output", dir_->File("fifo.exr")}, dir_->path());
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find(fifo + ": cannot write the convergence log: a pipe that no program reads"),
            std::string::npos) << r.err;
}

// The day's review: a convergence log given the --stats file's name, or an image's, made the job
// refuse itself as "another raystack render is writing" (its own locks). Said as what it is,
// before anything is opened (the stats file of an earlier run is left as it was).
TEST_F(RenderCli, AConvergenceLogIsAFileOfItsOwn) {
  std::ofstream(dir_->File("same.txt")) << "earlier";
  ProcessResult r = RunProcess({kRaystack, "render", Scene(), "-q", "--no-png", "--stats",
                                dir_->File("same.txt"), "--convergence-log",
                                dir_->File("./same.txt")},
                               dir_->path());
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("--convergence-log " + dir_->File("./same.txt") + " is the --stats file"), std::string::npos) << r.err;
  EXPECT_EQ(Slurp(dir_->File("same.txt")), "earlier");
  r = RunProcess({kRaystack, "render", Scene(), "-q", "--output", dir_->File("o2.exr"),
                  "--convergence-log", dir_->File("o2.png")}, dir_->path());
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("is " + dir_->File("o2.png") + ", an image of this job's output"),
            std::string::npos) << r.err;
  // The standard output sent to a file is a stream, written in place: a locked open emptied it,
  // and the run's lines before the log went with it.
  r = RunProcess({"/bin/sh", "-c", std::string(kRaystack) + " render " + Scene() + " --no-png " +
                  "--output " + dir_->File("o3.exr") + " --convergence-log /dev/stdout > " +
                  dir_->File("both.txt")}, dir_->path());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const std::string both = Slurp(dir_->File("both.txt"));
  EXPECT_NE(both.find("frame,event,pass,"), std::string::npos) << both;
  EXPECT_LT(both.find("reads: "), both.find("frame,event,pass,")) << both;
}

// Whitted sends a shadow ray from every hit to every light: at 1,024 lights a thread that opened
// more tiles while its rays waited for blocks held 8 tiles' worth (839 MB at 128 x 128, the day's
// review). It opens more only while fewer than RayThread::kMostWaitingToOpenMore (2^20) wait, so
// a thread's stack stays near that and one tile (1,024 pixels x 1,024 lights).
TEST_F(RenderCli, ManyLightsKeepTheStackBounded) {
  std::string lights;
  for (int i = 0; i < 1024; ++i)
    lights += StrFormat(R"(%s{ "type": "point", "position": [%d, 8, %d], "intensity": [0.1, 0.1, 0.1] })",
                        i ? "," : "", i % 32 - 16, i / 32 - 16);
  const std::string scene = WriteScene(R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 128, "height": 128 },
      "lights": [ )" + lights + R"( ], "output": "lights.exr" })");
  const ProcessResult r = RunProcess({kRaystack, "render", scene, "--threads", "1", "--cache-mb", "0.2",
                                      "--coarse-rounds", "off", "--no-png", "-q", "--tile-size", "32",
                                      "--stats", dir_->File("lights.json")}, dir_->path());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string text = prep::testing::Slurp(dir_->File("lights.json"));
  const size_t at = text.find("\"peak_stack_rays\": ");
  ASSERT_NE(at, std::string::npos) << text;
  const uint64_t peak = std::stoull(text.substr(at + 19));
  // The bound: below 2^20 waiting rays a thread may open one more tile, of at most 32 x 32
  // pixels x (1,024 shadow rays + 1). Without it a thread opens up to 8 tiles (13 M rays in the
  // review's run). Measured here: 0.86 M to 1.69 M (a second tile opens when every ray waits
  // while fewer than 2^20 do, which depends on the loader's pace: a bound of 1.6 M failed 2
  // runs in 5 on the thirty-second session's machine).
  EXPECT_LE(peak, (uint64_t{1} << 20) + 32u * 32u * 1025u) << text;  // (kMostWaitingToOpenMore)
  EXPECT_GT(peak, 100000u) << "the scene must make many rays wait";
}

// A --stats file that cannot be written was found after the render (which then failed, its
// figures lost); now before it starts.
TEST_F(RenderCli, AStatsFileThatCannotBeWrittenIsFoundBeforeTheRender) {
  const ProcessResult r = RunProcess({kRaystack, "render", Scene(), "--stats",
                                      dir_->File("none/stats.json"), "-q"}, dir_->path());
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("--stats: " + dir_->File("none/stats.json") + ": cannot write"), std::string::npos)
      << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir_->File("out.exr"))) << "it rendered first";
  // A folder (a hostile-input review: found after the whole job).
  const ProcessResult folder = RunProcess({kRaystack, "render", Scene(), "--stats", dir_->path(), "-q"},
                                          dir_->path());
  EXPECT_EQ(folder.exit_code, 1) << folder.err;
  EXPECT_NE(folder.err.find("--stats " + dir_->path() + " is a folder"), std::string::npos) << folder.err;
  EXPECT_FALSE(std::filesystem::exists(dir_->File("out.exr"))) << "it rendered first";
}

// From the review of that fix: a failure before any pixel had all its samples wrote the frame
// so far anyway, over a finished image of an earlier run, which --resume could not use and a
// plain run then refused as unfinished. With nothing to keep, nothing is written.
TEST_F(RenderCli, AFailureWithNothingToKeepLeavesTheOutputAsItWas) {
  const std::string scene = PathScene(16);
  const std::vector<std::string> common = {kRaystack, "render", scene, "--cache-mb", "0.2",
                                           "--threads", "1", "-q", "--no-png"};
  ASSERT_EQ(RunProcess(common, dir_->path()).exit_code, 0);
  const std::string finished = prep::testing::Slurp(dir_->File("out.exr"));
  std::vector<std::string> failing = common;  // progressive passes: nothing finished early on
  failing.insert(failing.end(), {"--fault-fail-read", "5"});
  const ProcessResult r = RunProcess(failing, dir_->path());
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("yet, so nothing is kept for --resume, and " + dir_->File("out.exr") +
                       " is left as it was"),
            std::string::npos) << r.err;
  EXPECT_TRUE(prep::testing::Slurp(dir_->File("out.exr")) == finished) << "the finished image was replaced";
  EXPECT_EQ(RunProcess(common, dir_->path()).exit_code, 0);
}

TEST_F(RenderCli, BadInputIsAClearError) {
  struct Case {
    std::vector<std::string> args;
    std::string message;
    int exit_code;
  };
  const std::string good = Scene();
  const std::string bad_json = dir_->File("bad.json");
  std::ofstream(bad_json) << "{ \"store\": \"store\", \"camera\": { \"fov_y_deg\": 400 } }";
  const std::string no_store = dir_->File("nostore.json");
  std::ofstream(no_store) << R"({ "store": "missing", "camera": { "position": [0, 5, 10], "look_at": [0, 0, 0] } })";
  const std::vector<Case> cases = {
      {{kRaystack, "render", good, "--cache-mb", "0.001"}, "smaller than the largest block", 1},
      {{kRaystack, "render", good, "--mode", "fast"}, "--mode must be", 2},
      // Found by a real-model user test, 2026-11-26: out of range was "not a number".
      {{kRaystack, "render", good, "--cache-mb", "0"}, "--cache-mb 0: must be from 0.001 to 16777216 (MiB)", 2},
      {{kRaystack, "render", good, "--threads", "x"}, "--threads: 'x' is not a number; give one from 1", 2},
      {{kRaystack, "render", good, "--frobnicate"}, "unknown option", 2},
      // A new user's GNU habit: the value goes after a space here.
      {{kRaystack, "render", good, "--spp=4"}, "unknown option --spp=4 (no option takes '=': an option's value, if it takes one, follows it after a space;", 2},
      // Found by a helper reading the docs: numbers the option's type cannot hold were "not a
      // number", and options that only another option uses were taken and did nothing.
      {{kRaystack, "render", good, "--threads", "99999999999"}, "--threads 99999999999: must be from 1 to 64", 2},
      {{kRaystack, "render", good, "--spp", "-1"}, "--spp -1: must be from 1", 2},
      {{kRaystack, "render", good, "--threads", "1.5"}, "--threads 1.5: must be a whole number written in digits, from 1", 2},
      // The day's review: beyond a type's range was "not a number", whole-number bounds
      // printed as 1e+12, and "+5" refused.
      {{kRaystack, "render", good, "--exposure", "1e999"}, "--exposure 1e999: must be from -64 to 64", 2},
      {{kRaystack, "render", good, "--fault-kill-after-tiles", "1e13"}, "must be from 1 to 1000000000000", 2},
      {{kRaystack, "render", good, "--threads", "+5", "--mode", "fast"}, "--mode must be", 2},
      {{kRaystack, "render", good, "--reference", "r.exr"}, "add --convergence-log FILE", 2},
      {{kRaystack, "render", good, "--fault-fail-checkpoints", "1"}, "add --checkpoint-s S", 2},
      {{kRaystack, "render"}, "scene file is required", 2},
      {{kRaystack, "render", dir_->File("absent.json")}, "absent.json", 1},
      {{kRaystack, "render", bad_json}, "fov_y_deg", 1},
      {{kRaystack, "render", no_store}, "missing", 1},
      {{kRaystack, "render", good, "--output", "/nonexistent-dir/x.exr"}, "/nonexistent-dir", 1},
      {{kRaystack, "frobnicate"}, "usage", 2},
  };
  for (const Case& c : cases) {
    const ProcessResult r = RunProcess(c.args, dir_->path());
    EXPECT_EQ(r.exit_code, c.exit_code) << c.args.back() << ": " << r.err;
    EXPECT_NE(r.err.find(c.message), std::string::npos) << "stderr was: " << r.err;
  }
  const ProcessResult help = RunProcess({kRaystack, "render", "--help"}, dir_->path());
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_NE(help.out.find("--cache-mb"), std::string::npos);
}

}  // namespace
}  // namespace raystack::testing
