// `mpirun -np N raystack render` as a user runs it: rank 0 the master, ranks 1..N-1 slaves.
// The EXR equals the one-process EXR byte for byte (Whitted and seeded path tracing, two
// cameras); a damaged block ends the whole job with an error naming it, never a hang.

#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdio>

#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "common/base/process_names.h"
#include "common/base/temp_dir.h"
#include "tests/prep/run_process.h"
#include "tests/support/convergence_csv.h"
#include "tests/support/memory_cgroup.h"
#include "tests/support/older_store.h"
#include "tests/support/store_dir_fixture.h"

namespace raystack::testing {
namespace {

using prep::testing::kPrepBinary;
using prep::testing::ProcessResult;
using prep::testing::RunProcess;
using prep::testing::Slurp;

const std::string& kRaystack = kRaystackBinary;

class DistributedCli : public StoreDirFixture {
 protected:
  void SetUp() override { MakeStore("spheres:30000"); }

  // A scene of two cameras looking at the spheres; the second at `second_position` (JSON).
  std::string Scene(const std::string& integrator,
                    const std::string& second_position = "[4, 3, 6]",
                    const std::string& name = "scene.json") {
    const std::string path = dir_->File(name);
    std::ofstream(path) << R"({ "store": "store",
      "cameras": [ { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 72, "height": 48 },
                   { "position": )" << second_position << R"(, "look_at": [0, 0.5, 0], "width": 72, "height": 48 } ],
      "lights": [ { "type": "point", "position": [3, 8, 4], "intensity": [100, 100, 100] } ],
      "materials": { "default": { "type": "diffuse", "albedo": [0.7, 0.6, 0.5] } },
      "integrator": )" << integrator << R"(,
      "output": "out.exr" })";
    return path;
  }

  // Renders with `np` ranks (0: without mpirun), 2 ray threads each, a small block cache.
  ProcessResult Render(const std::string& scene, int np, const std::string& out,
                       const std::string& blocks = "loc",
                       const std::vector<std::string>& extra = {}) {
    std::vector<std::string> argv;
    if (np > 0)
      argv = {RAYSTACK_MPIRUN, "--allow-run-as-root", "--oversubscribe", "-np", std::to_string(np)};
    // Open MPI 4.1 keeps the other ranks running when one dies.
    if (np > 0 && !extra.empty()) argv.push_back("--enable-recovery");
    for (const std::string& a : {kRaystack, std::string("render"), scene, std::string("--threads"),
                                 std::string("2"), std::string("--cache-mb"), std::string("1"),
                                 std::string("--output"), out, std::string("--no-png"),
                                 std::string("--blocks"), blocks, std::string("-q")})
      argv.push_back(a);
    for (const std::string& a : extra) argv.push_back(a);
    if (np > 0) argv[0] = RAYSTACK_MPIRUN;
    return RunProcess(argv, dir_->path());
  }
};

// The jobs of these tests run in a real cgroup-v1 memory cap of 256 MB, on the default scene's
// 2 M triangles (~61 MB of decoded blocks).
class DistributedMemory : public ::testing::Test {
 protected:
  void SetUp() override {
    std::string why;
    group_ = MemoryCgroup::CreateOwnChild("raystack-slave-cap", &why);
    if (!group_) GTEST_SKIP() << "no cgroup-v1 memory cap possible: " << why;
    ASSERT_TRUE(group_->Limit(uint64_t{256} << 20)) << "cannot set the limit of " << group_->path();
    Expected<TempDir> dir = TempDir::Create();
    ASSERT_TRUE(dir.ok());
    dir_ = std::make_unique<TempDir>(std::move(*dir));
    const ProcessResult prep = RunProcess(
        {kPrepBinary, "--generate", "spheres:2000000", "-o", dir_->File("store"), "-q"}, dir_->path());
    ASSERT_EQ(prep.exit_code, 0) << prep.err;
    std::ofstream(dir_->File("scene.json")) << R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 48, "height": 32 } })";
  }
  // mpirun -np `np` in the cap, with --mode `mode`.
  ProcessResult Render(int np, const std::string& mode) {
    return RunProcess({RAYSTACK_MPIRUN, "--allow-run-as-root", "--oversubscribe", "-np",
                       std::to_string(np), kRaystack, "render", dir_->File("scene.json"), "--mode",
                       mode, "--no-png", "-q", "--output", dir_->File("out.exr")},
                      dir_->path(), group_->Joiner());
  }
  std::unique_ptr<MemoryCgroup> group_;
  std::unique_ptr<TempDir> dir_;
};

// Found by a user with a model too big for RAM: under mpirun a slave never checked its memory,
// and one whose engine could not fit was killed by the kernel, the master seeing only a rank gone
// silent. Now each slave checks its own machine's (or cgroup's) room before it starts and the
// job ends with why, naming the host.
TEST_F(DistributedMemory, ASlaveWhoseEngineCannotFitSaysSoNamingItsHost) {
  // --mode bvh's tree would peak at ~360 MB beside ~60 MB of blocks: more than the cap.
  const ProcessResult r = Render(3, "bvh");
  ASSERT_NE(r.exit_code, 125) << "the child could not join " << group_->path();
  EXPECT_EQ(r.signal, 0) << r.err;
  EXPECT_NE(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("needs about"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("of memory for every block and the one BVH over every triangle (--mode bvh)"),
            std::string::npos) << r.err;
}

// Slaves that share a machine share its memory: each checked its own engine against the room
// left, all at the same moment, so five slaves whose blocks fit one at a time started together
// and were killed by the kernel as they loaded. Now each counts the slaves on its machine (Open
// MPI's environment: OMPI_COMM_WORLD_LOCAL_SIZE): --mode incore's blocks fit once, not five times.
TEST_F(DistributedMemory, SlavesOnOneMachineCheckTheirMemoryTogether) {
  const auto render = [&](int np) { return Render(np, "incore"); };
  // One slave's blocks fit: the check does not refuse what fits.
  const ProcessResult one = render(2);
  ASSERT_NE(one.exit_code, 125) << "the child could not join " << group_->path();
  ASSERT_EQ(one.exit_code, 0) << one.err;
  const ProcessResult five = render(6);
  EXPECT_EQ(five.signal, 0) << five.err;
  EXPECT_NE(five.exit_code, 0) << five.err;
  EXPECT_NE(five.err.find("MB for each of its 5 slaves"), std::string::npos) << five.err;
  EXPECT_NE(five.err.find("or fewer slaves on this machine"), std::string::npos) << five.err;
}

TEST_F(DistributedCli, ImagesEqualTheOneProcessImage) {
  for (const std::string integrator :
       {R"({ "type": "whitted", "max_depth": 3, "spp": 1, "seed": 1 })",
        R"({ "type": "path", "max_depth": 4, "spp": 2, "seed": 5 })"}) {
    const std::string scene = Scene(integrator);
    const ProcessResult one = Render(scene, 0, dir_->File("one.exr"));
    ASSERT_EQ(one.exit_code, 0) << one.err;
    for (const auto& [np, blocks] : std::vector<std::pair<int, std::string>>{
             {1, "loc"}, {3, "loc"}, {5, "loc"}, {3, "rem"}, {5, "rem"}}) {
      const std::string out = dir_->File("np" + std::to_string(np) + ".exr");
      const ProcessResult r = Render(scene, np, out, blocks);
      ASSERT_EQ(r.exit_code, 0) << "np " << np << ": " << r.err << r.out;
      for (const char* frame : {"-0", "-1"}) {  // both cameras
        const std::string a = Slurp(dir_->File(std::string("one") + frame + ".exr"));
        const std::string b = Slurp(dir_->File("np" + std::to_string(np) + frame + ".exr"));
        ASSERT_FALSE(a.empty());
        EXPECT_TRUE(a == b) << "np " << np << " " << blocks << ", frame '" << frame << "', "
                            << integrator;
      }
    }
  }
}

// Frames of one size share one film, cleared in between (Film::Clear): nothing of a frame may
// leak into the next. The same camera twice gives the same EXR twice, one process and mpirun.
TEST_F(DistributedCli, ARepeatedCameraGivesTheSameFrameAgain) {
  const std::string path =
      Scene(R"({ "type": "path", "max_depth": 3, "spp": 2, "seed": 4 })", "[0, 5, 10]", "twice.json");
  for (int np : {0, 3}) {
    const std::string out = dir_->File("twice" + std::to_string(np) + ".exr");
    const ProcessResult r = Render(path, np, out);
    ASSERT_EQ(r.exit_code, 0) << "np " << np << ": " << r.err << r.out;
    const std::string first = Slurp(dir_->File("twice" + std::to_string(np) + "-0.exr"));
    const std::string second = Slurp(dir_->File("twice" + std::to_string(np) + "-1.exr"));
    ASSERT_FALSE(first.empty());
    EXPECT_TRUE(first == second) << "np " << np;
  }
}

// Slaves reading past the page cache (--direct-io on: their owners' shares under rem too)
// render the one-process image, and each says so in the master's per-slave figures.
TEST_F(DistributedCli, DirectReadsUnderMpirunKeepTheImageAndAreReported) {
  const std::string scene = Scene(R"({ "type": "whitted", "max_depth": 3, "spp": 1, "seed": 1 })");
  const ProcessResult one = Render(scene, 0, dir_->File("one.exr"));
  ASSERT_EQ(one.exit_code, 0) << one.err;
  for (const std::string blocks : {"loc", "rem"}) {
    const std::string out = dir_->File("direct-" + blocks + ".exr");
    const ProcessResult r = Render(scene, 3, out, blocks,
                                   {"--direct-io", "on", "--stats", dir_->File("stats.json")});
    ASSERT_EQ(r.exit_code, 0) << blocks << ": " << r.err << r.out;
    for (const char* frame : {"-0", "-1"}) {
      const std::string a = Slurp(dir_->File(std::string("one") + frame + ".exr"));
      ASSERT_FALSE(a.empty());
      EXPECT_TRUE(a == Slurp(dir_->File("direct-" + blocks + frame + ".exr"))) << blocks << frame;
    }
    // 2 frames x 2 slaves, each with its flag.
    const std::string stats = Slurp(dir_->File("stats.json"));
    size_t direct = 0;
    for (size_t at = stats.find("\"direct_reads\": true"); at != std::string::npos;
         at = stats.find("\"direct_reads\": true", at + 1))
      ++direct;
    EXPECT_EQ(direct, 4u) << stats;
    EXPECT_EQ(stats.find("\"direct_reads\": false"), std::string::npos) << stats;
  }
}

// Found by a researcher: a job's --stats had per slave fewer figures than a one-process run's,
// under other names (busy_seconds, ray_threads, rays a number), so T_io and bytes per waiting ray
// could not be had from a distributed run. Now each slave's entry has the one-process figures
// under their names, and the rays the slaves traced add up to the one process's, type by type.
TEST_F(DistributedCli, EachSlavesStatisticsHaveTheOneProcessFigures) {
  const std::string scene = Scene(R"({ "type": "path", "max_depth": 3, "spp": 2, "seed": 5 })");
  const ProcessResult one = Render(scene, 0, dir_->File("one.exr"), "loc", {"--stats", dir_->File("one.json")});
  ASSERT_EQ(one.exit_code, 0) << one.err;
  // Not quiet (Render's -q): the master's per-rank lines are checked too.
  const ProcessResult job = RunProcess(
      {RAYSTACK_MPIRUN, "--allow-run-as-root", "--oversubscribe", "-np", "3", kRaystack, "render",
       scene, "--threads", "2", "--cache-mb", "1", "--output", dir_->File("job.exr"), "--no-png",
       "--blocks", "loc", "--stats", dir_->File("job.json")},
      dir_->path());
  ASSERT_EQ(job.exit_code, 0) << job.err;
  const nlohmann::json local = nlohmann::json::parse(Slurp(dir_->File("one.json")));
  const nlohmann::json slaves = nlohmann::json::parse(Slurp(dir_->File("job.json")));
  ASSERT_EQ(local.size(), 2u);  // two cameras
  ASSERT_EQ(slaves.size(), 2u);
  for (size_t f = 0; f < 2; ++f) {
    // Each entry says which frame, image, size and run it is (it was told by position only).
    for (const auto& [entry, image] : {std::pair{local[f], dir_->File("one-" + std::to_string(f) + ".exr")},
                                       std::pair{slaves[f], dir_->File("job-" + std::to_string(f) + ".exr")}}) {
      EXPECT_EQ(entry["frame"], f);
      EXPECT_EQ(entry["output"], image);
      EXPECT_EQ(entry["width"], 72);
      EXPECT_EQ(entry["height"], 48);
      EXPECT_EQ(entry["spp"], 2);
      EXPECT_TRUE(entry["stopped"].is_null());
      EXPECT_TRUE(entry["build"].is_string() && !entry["build"].get<std::string>().empty());
      EXPECT_EQ(entry["host"], HostName());
    }
    ASSERT_EQ(slaves[f]["slaves"].size(), 2u);
    nlohmann::json sum = {{"primary", 0}, {"shadow", 0}, {"specular", 0}, {"diffuse", 0}};
    uint64_t total = 0;
    for (const nlohmann::json& s : slaves[f]["slaves"]) {
      for (const char* key : {"threads", "rays", "rays_total", "samples", "blocks_loaded",
                              "blocks_distinct", "bytes_read", "reads", "direct_reads",
                              "block_visits", "cache_hit_rate", "loader_busy_seconds",
                              "ray_idle_seconds", "ray_tile_wait_seconds", "ray_busy_seconds",
                              "ray_cpu_seconds", "loader_cpu_seconds", "cache_budget_bytes",
                              "cache_peak_bytes", "evictions", "peak_stack_bytes",
                              "peak_stack_rays", "peak_rss_bytes"}) {
        ASSERT_TRUE(s.contains(key)) << key << " in " << s;
        // The same kind of value (a number of either kind: "%g" writes 0.0 as 0).
        EXPECT_TRUE(s[key].is_number() ? local[f][key].is_number() : s[key].type() == local[f][key].type())
            << key << ": " << s[key] << " against " << local[f][key];
      }
      for (auto& [type, n] : sum.items()) n = n.get<uint64_t>() + s["rays"][type].get<uint64_t>();
      total += s["rays_total"].get<uint64_t>();
      EXPECT_GT(s["peak_rss_bytes"].get<uint64_t>(), uint64_t{1} << 20);
      EXPECT_GE(s["cache_hit_rate"].get<double>(), 0.0);
      EXPECT_LE(s["cache_hit_rate"].get<double>(), 1.0);
      EXPECT_LE(s["cache_peak_bytes"].get<uint64_t>(), s["cache_budget_bytes"].get<uint64_t>());
    }
    EXPECT_EQ(sum, local[f]["rays"]) << "frame " << f;
    EXPECT_EQ(total, local[f]["rays_total"].get<uint64_t>()) << "frame " << f;
  }
  EXPECT_EQ(slaves[0]["slaves"][0]["host"], HostName());
  // And the master's per-rank lines say the host, the cache's figures and the peak RSS.
  EXPECT_NE(job.out.find("  rank 1 (on " + HostName() + "): "), std::string::npos) << job.out;
  EXPECT_NE(job.out.find("; cache: hit rate "), std::string::npos) << job.out;
  EXPECT_NE(job.out.find("peak RSS "), std::string::npos) << job.out;
}

// Found by the day's review: an output name that is not UTF-8 (a Latin-1 é) went into --stats
// as it was, and the file was not JSON. Bytes that are not UTF-8 are escaped; quotes too.
TEST_F(DistributedCli, StatisticsStayJsonWhateverTheOutputsName) {
  const std::string scene = Scene(R"({ "type": "whitted" })");
  const std::string out = dir_->File("caf\xe9 \"q\".exr");
  const ProcessResult r = Render(scene, 0, out, "loc", {"--stats", dir_->File("stats.json")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  nlohmann::json stats;
  ASSERT_NO_THROW(stats = nlohmann::json::parse(Slurp(dir_->File("stats.json"))));
  EXPECT_EQ(stats[0]["output"], dir_->File("caf\u00e9 \"q\"-0.exr"));
  // Byte patterns that only look like UTF-8 (the second review): an overlong '/', a surrogate.
  const std::string odd = dir_->File("x\xc0\xaf-\xed\xa0\x80.exr");
  ASSERT_EQ(Render(scene, 0, odd, "loc", {"--stats", dir_->File("odd.json")}).exit_code, 0);
  ASSERT_NO_THROW(stats = nlohmann::json::parse(Slurp(dir_->File("odd.json"))));
  EXPECT_EQ(stats[0]["output"], dir_->File("x\u00c0\u00af-\u00ed\u00a0\u0080-0.exr"));
}

// kill -9 of a slave mid-render (the slave does it to itself at its 3rd tile, so the test
// knows it happens mid-render), a slave whose whole process stops for longer than the
// master waits for word from it, and a slave whose store reads fail: the master drops it, the
// others render its unfinished tiles (with --blocks rem, the others read the killed owner's
// blocks from disk), and the image equals the one-process image.
TEST_F(DistributedCli, ALostSlaveCostsTimeNeverPixels) {
  const std::string scene = Scene(R"({ "type": "path", "max_depth": 3, "spp": 2, "seed": 9 })");
  const ProcessResult one = Render(scene, 0, dir_->File("one.exr"));
  ASSERT_EQ(one.exit_code, 0) << one.err;
  struct Case {
    std::string name, blocks;
    std::vector<std::string> faults;
    std::string why;
  };
  for (const Case& c : std::vector<Case>{
           {"killed", "loc", {"--fault-rank", "2", "--fault-kill-after-tiles", "3"}, "is lost"},
           {"killed", "rem", {"--fault-rank", "2", "--fault-kill-after-tiles", "3"}, "is lost"},
           // Alive but silent past --lost-after (a stalled node): dropped as lost, and told
           // so, so it ends with the job rather than wait for tiles nobody gives it.
           {"stalled", "loc",
            {"--fault-rank", "2", "--fault-stall-after-tiles", "3", "--fault-stall-s", "4"},
            "is lost"},
           // With --blocks rem the peers of a stalled owner give up on it while it still
           // answers (late answers are dropped), and an owner that cannot read its blocks
           // sends its askers to their own disks.
           {"stalled", "rem",
            {"--fault-rank", "2", "--fault-stall-after-tiles", "3", "--fault-stall-s", "4"},
            "is lost"},
           // Frozen for longer than the job (a hung node): found by an operator, mpirun
           // waited for it after the image was written, holding the allocation; the master
           // now ends such a rank by force (without the fix this case waits 10 minutes).
           {"frozen", "loc",
            {"--fault-rank", "2", "--fault-stall-after-tiles", "3", "--fault-stall-s", "600"},
            "is lost"},
           {"unreadable", "loc", {"--fault-rank", "3", "--fault-fail-read", "0"}, "failed"},
           {"unreadable", "rem", {"--fault-rank", "3", "--fault-fail-read", "0"}, "failed"}}) {
    std::vector<std::string> extra = c.faults;
    extra.insert(extra.end(), {"--lost-after", "2"});
    const std::string out = dir_->File(c.name + "-" + c.blocks + ".exr");
    const ProcessResult r = Render(scene, 4, out, c.blocks, extra);
    // (Under --enable-recovery mpirun exits 0 whatever the ranks do: the images below are
    // what shows that the job succeeded.)
    ASSERT_EQ(r.exit_code, 0) << c.name << " " << c.blocks << ": " << r.err << r.out;
    EXPECT_NE(r.err.find(c.why), std::string::npos) << c.name << ": " << r.err;
    // Where it ran, for the operator (found by one: the warnings named no host).
    EXPECT_NE(r.err.find(" (on " + HostName() + ") " + c.why), std::string::npos)
        << c.name << ": " << r.err;
    for (const char* frame : {"-0", "-1"}) {
      const std::string a = Slurp(dir_->File(std::string("one") + frame + ".exr"));
      const std::string b = Slurp(dir_->File(c.name + "-" + c.blocks + frame + ".exr"));
      ASSERT_FALSE(a.empty());
      EXPECT_TRUE(a == b) << c.name << " " << c.blocks << ", frame '" << frame << "'";
    }
  }
}

// Progressive passes in another order and size, a convergence log and a reference under
// mpirun: the same bytes as the one-process image, and the log's last row of each frame has
// every sample, the slaves' rays, and RMSE 0 against that image.
TEST_F(DistributedCli, ConvergenceLogAndStopRulesUnderMpirun) {
  const std::string scene = Scene(R"({ "type": "path", "max_depth": 3, "spp": 4, "seed": 2 })");
  ASSERT_EQ(Render(scene, 0, dir_->File("one.exr")).exit_code, 0);
  const ProcessResult r =
      Render(scene, 3, dir_->File("np3.exr"), "loc",
             {"--pixel-order", "scanline", "--pass-spp", "3", "--convergence-log",
              dir_->File("log.csv"), "--reference", dir_->File("one.exr")});
  ASSERT_EQ(r.exit_code, 0) << r.err << r.out;
  for (const char* frame : {"-0", "-1"})
    EXPECT_TRUE(Slurp(dir_->File(std::string("one") + frame + ".exr")) ==
                Slurp(dir_->File(std::string("np3") + frame + ".exr"))) << frame;
  const std::vector<LogRow> rows = ReadConvergenceLog(dir_->File("log.csv"));
  int ends = 0;
  for (const LogRow& row : rows) {
    if (row.event != "end") continue;
    EXPECT_EQ(row.frame, static_cast<uint32_t>(ends));
    EXPECT_EQ(row.samples, 72u * 48u * 4u);
    EXPECT_GT(row.rays, row.samples);
    EXPECT_EQ(row.rmse, 0.0);
    ++ends;
  }
  EXPECT_EQ(ends, 2);

  // A time limit far below what 4096 samples per pixel take: the master stops handing out
  // tiles, the slaves finish theirs, and the job ends cleanly with a partial image.
  const ProcessResult t = Render(scene, 3, dir_->File("limited.exr"), "loc",
                                 {"--spp", "4096", "--time-limit", "0.5", "--convergence-log",
                                  dir_->File("limited.csv")});
  ASSERT_EQ(t.exit_code, 0) << t.err << t.out;
  int stops = 0;
  for (const LogRow& row : ReadConvergenceLog(dir_->File("limited.csv"))) {
    stops += row.event == "stop";
    if (row.event == "end") {
      EXPECT_LT(row.samples, 72u * 48u * 4096u);
    }
  }
  EXPECT_EQ(stops, 2);  // both frames
}

// A scene every rank refuses: the master reports it once and ends the job on every rank,
// which exits 1 (each slave calling MPI_Abort at once left mpirun hung or crashed, and
// printed the error once per rank).
TEST_F(DistributedCli, ABadSceneEndsTheJobWithOneError) {
  const std::string scene = dir_->File("bad.json");
  std::ofstream(scene) << R"({ "store": "store", "camera": {}, "extra": 1 })";
  for (int attempt = 0; attempt < 3; ++attempt) {
    const ProcessResult r = Render(scene, 3, dir_->File("bad.exr"));
    EXPECT_EQ(r.exit_code, 1) << r.err;
    size_t count = 0;
    for (size_t at = r.err.find("extra: unknown key"); at != std::string::npos;
         at = r.err.find("extra: unknown key", at + 1))
      ++count;
    EXPECT_EQ(count, 1u) << r.err;
  }
}

// A store no rank can open: the slaves fail alike, and the job's error gives the cause once, not
// once a rank, without "its 0 unfinished tiles go to the other slaves" (a new user's review).
TEST_F(DistributedCli, AStoreNoRankCanOpenIsSaidOnce) {
  const std::string scene = dir_->File("nowhere.json");
  std::ofstream(scene) << R"({ "store": "nowhere.store", "camera": { "width": 32, "height": 24 },
    "lights": [ { "type": "point", "position": [0, 5, 0], "intensity": [10, 10, 10] } ] })";
  const ProcessResult r = Render(scene, 3, dir_->File("nowhere.exr"));
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("no slave is left to finish the frame: ranks 1 to 2: "), std::string::npos)
      << r.err;
  EXPECT_EQ(r.err.find("unfinished tiles"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("it had no tile in flight"), std::string::npos) << r.err;
}

// --blocks rem with a cache smaller than a slave's share of the store: the master says so once,
// before any slave starts (each slave used to fail on its own, after the job had begun).
TEST_F(DistributedCli, ARemShareTooLargeForTheCacheEndsTheJobBeforeItStarts) {
  const std::string scene = Scene(R"({ "type": "whitted" })");
  std::vector<std::string> argv = {RAYSTACK_MPIRUN, "--allow-run-as-root", "--oversubscribe",
                                   "-np", "3", kRaystack, "render", scene, "--cache-mb", "0.05",
                                   "--blocks", "rem", "--no-png", "--output", dir_->File("rem.exr")};
  const ProcessResult r = RunProcess(argv, dir_->path());
  EXPECT_NE(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("a slave's share of the store"), std::string::npos) << r.err;
  // No frame began (progress lines go to stderr; two cameras: "frame 0 (1 of 2)").
  EXPECT_EQ(r.err.find("frame 0 ("), std::string::npos) << r.err;
}

// A scene with nothing to light it (found by a real-model user: the documented minimal scene
// on a store without emissive materials) renders black, and says so before it starts; one
// process or under mpirun, once.
TEST_F(DistributedCli, AnUnlitSceneIsAWarning) {
  const std::string unlit = dir_->File("unlit.json");
  std::ofstream(unlit) << R"({ "store": "store",
      "camera": { "position": [0, 5, 10], "look_at": [0, 0.5, 0], "width": 32, "height": 20 },
      "output": "out.exr" })";
  const std::string warning = "the scene has no light";
  for (const int np : {0, 3}) {
    SCOPED_TRACE(np);
    const ProcessResult r = Render(unlit, np, dir_->File("unlit.exr"));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const size_t at = r.err.find(warning);
    EXPECT_NE(at, std::string::npos) << r.err;
    if (at != std::string::npos) {
      EXPECT_EQ(r.err.find(warning, at + 1), std::string::npos) << r.err;
    }
  }
  const ProcessResult lit = Render(Scene(R"({ "type": "whitted" })"), 0, dir_->File("lit.exr"));
  ASSERT_EQ(lit.exit_code, 0) << lit.err;
  EXPECT_EQ(lit.err.find(warning), std::string::npos) << lit.err;
}

// With several cameras every frame's --reference is checked before the first frame renders:
// a missing one for the last camera ends the job before any image is written.
TEST_F(DistributedCli, AMissingReferenceOfALaterCameraIsFoundBeforeRendering) {
  const std::string scene = Scene(R"({ "type": "whitted" })");
  ASSERT_EQ(Render(scene, 0, dir_->File("ref.exr")).exit_code, 0);
  ASSERT_EQ(std::remove(dir_->File("ref-1.exr").c_str()), 0);
  for (const int np : {0, 3}) {
    const ProcessResult r = Render(scene, np, dir_->File("out.exr"), "loc",
                                   {"--reference", dir_->File("ref.exr"), "--convergence-log",
                                    dir_->File("log.csv")});
    EXPECT_NE(r.err.find("ref-1.exr: cannot read"), std::string::npos) << np << ": " << r.err;
    EXPECT_TRUE(Slurp(dir_->File("out-0.exr")).empty()) << np << ": frame 0 was rendered";
  }
}

// Every rank reads its own scene file and store (on a cluster, its host's copies): a rank whose
// copy differs would merge pixels of another image into this one. The master compares what
// each slave says it renders (its hello) and ends the job naming that rank, before any of its
// pixels; mpirun's MPMD form gives one rank other files here.
TEST_F(DistributedCli, ARankWithAnotherStoreOrSceneEndsTheJobNamingIt) {
  const prep::testing::ProcessResult other_store = RunProcess(
      {kPrepBinary, "--generate", "spheres:20000", "-o", dir_->File("store2"), "--target-block-kb",
       "8", "-q"},
      dir_->path());
  ASSERT_EQ(other_store.exit_code, 0) << other_store.err;
  // The same store converted before lights.bin existed: the same index, another image.
  ASSERT_TRUE(CopyAsOlderStore(dir_->File("store"), dir_->File("store-older")));
  const std::string integrator = R"({ "type": "whitted" })";
  const std::string scene = Scene(integrator);
  std::string text = Slurp(scene);
  auto write = [&](const std::string& name, const std::string& from, const std::string& to) {
    std::string changed = text;
    const size_t at = changed.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    if (at != std::string::npos) changed.replace(at, from.size(), to);
    std::ofstream(dir_->File(name)) << changed;
    return dir_->File(name);
  };
  struct Case {
    std::string scene, error;
  };
  for (const Case& c : {Case{write("other-store.json", R"("store": "store")", R"("store": "store2")"),
                             "reads another store than the master"},
                        Case{write("older-store.json", R"("store": "store")",
                                   R"("store": "store-older")"),
                             "reads another store than the master"},
                        Case{write("other-light.json", "[100, 100, 100]", "[100, 100, 90]"),
                             "read another scene than the master"},
                        Case{write("other-seed.json", R"("type": "whitted")",
                                   R"("type": "whitted", "seed": 2)"),
                             "read another scene than the master"}}) {
    SCOPED_TRACE(c.error + " (" + c.scene + ")");
    const std::string out = dir_->File("mixed.exr");
    std::vector<std::string> argv = {RAYSTACK_MPIRUN, "--allow-run-as-root", "--oversubscribe"};
    for (const auto& [np, file] : {std::pair<std::string, std::string>{"2", scene}, {"1", c.scene}})
      for (const std::string& a : {std::string("-np"), np, kRaystack, std::string("render"), file,
                                   std::string("--threads"), std::string("1"),
                                   std::string("--output"), out, std::string("--no-png"),
                                   std::string("--blocks"), std::string("loc"), std::string(":")})
        argv.push_back(a);
    argv.pop_back();  // the last ':'
    const ProcessResult r = RunProcess(argv, dir_->path());
    EXPECT_NE(r.exit_code, 0) << r.err;
    EXPECT_NE(r.err.find("rank 2 (on "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(c.error), std::string::npos) << r.err;
    EXPECT_TRUE(Slurp(dir_->File("mixed-0.exr")).empty()) << "an image was written";
    EXPECT_EQ(r.err.find("frame 0 ("), std::string::npos) << "a progress line before the error";
  }
  // The same files on every rank, through the same MPMD form: the image as ever.
  std::vector<std::string> same = {RAYSTACK_MPIRUN, "--allow-run-as-root", "--oversubscribe",
                                   "-np", "2", kRaystack, "render", scene, "--no-png", "--output",
                                   dir_->File("same.exr"), ":", "-np", "1", kRaystack, "render",
                                   scene, "--no-png", "--output", dir_->File("same.exr")};
  const ProcessResult r = RunProcess(same, dir_->path());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(Slurp(dir_->File("same-0.exr")).empty());
}

// `raystack --version` names the build every rank must share; the images record it too.
TEST_F(DistributedCli, TheVersionIsTheBuildTheImagesRecord) {
  const ProcessResult v = RunProcess({kRaystack, "--version"}, dir_->path());
  ASSERT_EQ(v.exit_code, 0) << v.err;
  ASSERT_EQ(v.out.rfind("raystack ", 0), 0u) << v.out;
  const std::string build = v.out.substr(9, v.out.find('\n') - 9);
  EXPECT_NE(build.find(" ("), std::string::npos) << build;  // version (commit)
  ASSERT_EQ(Render(Scene(R"({ "type": "whitted" })"), 0, dir_->File("v.exr")).exit_code, 0);
  EXPECT_NE(Slurp(dir_->File("v-0.exr")).find("build " + build + "\n"), std::string::npos);
}

TEST_F(DistributedCli, ADamagedBlockEndsTheJobNamingIt) {
  // Flip a byte in the middle of the block file.
  const std::string blocks = dir_->File("store/blocks.bin");
  std::fstream f(blocks, std::ios::in | std::ios::out | std::ios::binary);
  f.seekg(0, std::ios::end);
  const auto size = static_cast<std::streamoff>(f.tellg());
  char c;
  f.seekg(size / 2);
  f.read(&c, 1);
  c = static_cast<char>(c ^ 0x5a);
  f.seekp(size / 2);
  f.write(&c, 1);
  f.close();
  const std::string scene = Scene(R"({ "type": "whitted" })");
  const ProcessResult r = Render(scene, 3, dir_->File("bad.exr"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("damaged"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("block "), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("rank "), std::string::npos) << r.err;
}

// Under mpirun only the slaves need the store. Found by an operator: a master that could not read
// it (another host's filesystem, here a private mount namespace with an empty folder over it)
// resumed a checkpoint rendered from another model at the same path, and wrote the mixed image
// as complete: its provenance could not tell the stores apart. --resume now needs the index.
TEST_F(DistributedCli, AMasterThatCannotReadTheStoreRefusesToResume) {
  if (geteuid() != 0) GTEST_SKIP() << "a private mount namespace needs root (CI runs as root)";
  const std::string wrapper = dir_->File("blind-master.sh");
  std::filesystem::create_directories(dir_->File("empty"));
  std::ofstream(wrapper) << "#!/bin/sh\n"
                            "if [ \"$OMPI_COMM_WORLD_RANK\" = 0 ]; then\n"
                            "  exec unshare -m sh -c 'mount --bind \"$0\" \"$1\" || exit 125; shift; exec \"$@\"' "
                         << dir_->File("empty") << " " << dir_->File("store") << " \"$@\"\n"
                            "fi\n"
                            "exec \"$@\"\n";
  std::filesystem::permissions(wrapper, std::filesystem::perms::owner_all);
  const std::string scene = Scene(R"({ "type": "whitted", "max_depth": 3, "spp": 1, "seed": 1 })");
  const auto run = [&](const std::vector<std::string>& extra, const std::string& out = "blind.exr") {
    std::vector<std::string> argv = {RAYSTACK_MPIRUN, "--allow-run-as-root", "--oversubscribe", "-np",
                                     "3", wrapper, kRaystack, "render", scene, "--no-png", "-q",
                                     "--cache-mb", "1", "--output", dir_->File(out)};
    argv.insert(argv.end(), extra.begin(), extra.end());
    return RunProcess(argv, dir_->path());
  };
  // Without --resume the slaves render it (the store is theirs to read).
  const ProcessResult fresh = run({});
  if (fresh.err.find("unshare") != std::string::npos || fresh.exit_code == 125)
    GTEST_SKIP() << "no private mount namespace here: " << fresh.err;
  ASSERT_EQ(fresh.exit_code, 0) << fresh.err;
  const ProcessResult resumed = run({"--resume"});
  EXPECT_NE(resumed.exit_code, 0);
  EXPECT_NE(resumed.err.find("--resume: cannot read " + dir_->File("store") + "/index.bin here"),
            std::string::npos) << resumed.err;
  // With no checkpoint there is nothing to tell apart: a job that always passes --resume starts.
  const ProcessResult first = run({"--resume"}, "first.exr");
  EXPECT_EQ(first.exit_code, 0) << first.err;
}

}  // namespace
}  // namespace raystack::testing
