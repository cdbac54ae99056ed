// raystack-prep and raystack-info as a user meets them: exit codes and messages that name the
// problem, statistics after a good run, and --verify catching a damaged block.

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <regex>
#include <thread>

#include "common/base/file_lock.h"
#include "common/base/interrupt.h"
#include "common/base/process_names.h"
#include "common/base/temp_dir.h"
#include "common/store/store_reader.h"
#include "common/store/store_writer.h"
#include "tests/preview/background_process.h"
#include "tests/prep/run_process.h"
#include "tests/support/small_tmpfs.h"
#include "tests/support/test_dir.h"

namespace raystack::prep {
namespace {

using testing::kInfoBinary;
using testing::kPrepBinary;
using testing::ProcessResult;
using testing::RunProcess;

class PrepCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = raystack::testing::MakeTestDir();
    ASSERT_TRUE(dir_);
  }

  ProcessResult Prep(std::vector<std::string> args) {
    args.insert(args.begin(), kPrepBinary);
    return RunProcess(args, dir_->path());
  }
  ProcessResult Info(std::vector<std::string> args) {
    args.insert(args.begin(), kInfoBinary);
    return RunProcess(args, dir_->path());
  }

  // Expects a clean failure (an exit code, not a crash) whose stderr mentions every `words`.
  static void ExpectFailsNaming(const ProcessResult& r, const std::vector<std::string>& words) {
    EXPECT_EQ(r.signal, 0) << "crashed; stderr: " << r.err;
    EXPECT_GT(r.exit_code, 0) << "stderr: " << r.err;
    for (const std::string& w : words)
      EXPECT_NE(r.err.find(w), std::string::npos) << "stderr does not name '" << w << "': " << r.err;
  }

  // A conversion replacing a store is interrupted by `signal` (the test below).
  void ExpectAnInterruptLeavesTheOldStoreWhole(int signal);

  std::unique_ptr<TempDir> dir_;
};

// The harness itself: a run past its deadline is killed with what it started (a shell and
// the sleep it put in the background, as mpirun and its ranks), and says so.
TEST_F(PrepCliTest, ARunPastItsDeadlineIsKilledWithItsChildren) {
  const ProcessResult r = RunProcess({"/bin/sh", "-c", "sleep 600 & echo $!; wait"},
                                     dir_->path(), {}, /*deadline_seconds=*/1);
  EXPECT_TRUE(r.timed_out);
  EXPECT_EQ(r.signal, SIGKILL);
  EXPECT_NE(r.err.find("killed after 1 s"), std::string::npos) << r.err;
  // Where there is gdb, the stacks of the group's threads come with it (the sleep's, waiting).
  if (access("/usr/bin/gdb", X_OK) == 0) {
    EXPECT_NE(r.err.find("[run_process] its threads then:"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("sleep 600"), std::string::npos) << r.err;
  }
  // The background sleep went with the group: gone, or a zombie about to be reaped.
  const std::string stat_path = "/proc/" + std::to_string(std::atoi(r.out.c_str())) + "/stat";
  ASSERT_GT(std::atoi(r.out.c_str()), 0) << r.out;
  bool gone = false;
  for (int i = 0; i < 1000 && !gone; ++i) {
    const std::string stat = testing::Slurp(stat_path);
    gone = stat.empty() || stat.find(") Z ") != std::string::npos ||
           stat.find(") X ") != std::string::npos;
    if (!gone) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_TRUE(gone) << testing::Slurp(stat_path);
}

TEST_F(PrepCliTest, HelpMentionsEveryOption) {
  const ProcessResult r = Prep({"--help"});
  EXPECT_EQ(r.exit_code, 0);
  for (const char* option :
       {"-o", "--output", "--generate", "--replicate", "--target-block-kb", "--max-block-kb",
        "--mem-limit", "--threads", "--temp-dir", "--no-shuffle", "--stats-json", "-q",
        "--quiet", "--help"})
    EXPECT_NE(r.out.find(option), std::string::npos) << "--help does not mention " << option;
  EXPECT_EQ(Prep({"-h"}).exit_code, 0);
}

TEST_F(PrepCliTest, MissingOutputFails) {
  ExpectFailsNaming(Prep({"--generate", "sphere:100"}), {"-o"});
}

// Found by a helper reading the docs: no arguments said "no output store given" (render and
// info print their usage), and only `raystack` had --version.
TEST_F(PrepCliTest, NoArgumentsPrintTheUsageAndVersionSaysTheBuild) {
  ProcessResult r = Prep({});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("usage: raystack-prep INPUT... -o STORE"), std::string::npos) << r.err;
  r = Prep({"--version"});
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_EQ(r.out.rfind("raystack-prep 0.", 0), 0u) << r.out;
  r = Info({"--version"});
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_EQ(r.out.rfind("raystack-info 0.", 0), 0u) << r.out;
}

// Found by a helper reading the docs: -o naming a folder of the user's own files wrote the
// store's among them (and a failed conversion's clean-up would then have removed a folder it
// took for its own). Such a folder is refused; a store's folder is replaced.
TEST_F(PrepCliTest, AFolderOfOtherFilesIsRefusedAndAStoreIsReplaced) {
  std::filesystem::create_directory(dir_->File("photos"));
  std::ofstream(dir_->File("photos/holiday.jpg")) << "jpeg";
  ProcessResult r = Prep({"--generate", "sphere:100", "-o", dir_->File("photos"), "-q"});
  ExpectFailsNaming(r, {"photos: holds other files ('holiday.jpg')", "a folder of its own"});
  EXPECT_TRUE(std::filesystem::exists(dir_->File("photos/holiday.jpg")));
  EXPECT_FALSE(std::filesystem::exists(dir_->File("photos/index.bin")));
  ASSERT_EQ(Prep({"--generate", "sphere:100", "-o", dir_->File("s"), "-q"}).exit_code, 0);
  r = Prep({"--generate", "sphere:200", "-o", dir_->File("s"), "-q"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
}

TEST_F(PrepCliTest, UnknownOptionFails) {
  ExpectFailsNaming(Prep({"--generate", "sphere:100", "-o", dir_->File("s"), "--frobnicate"}),
                    {"--frobnicate"});
}

TEST_F(PrepCliTest, BadReplicateFails) {
  for (const char* bad : {"2,2", "0,1,1", "a,b,c", "1,1,5000", "2,2,2,2", "2,2,2x"}) {
    SCOPED_TRACE(bad);
    ExpectFailsNaming(
        Prep({"--generate", "sphere:100", "-o", dir_->File("s"), "--replicate", bad}),
        {"--replicate", bad});
  }
}

TEST_F(PrepCliTest, BadNumberFails) {
  ExpectFailsNaming(Prep({"--generate", "sphere:100", "-o", dir_->File("s"), "--mem-limit", "12x"}),
                    {"--mem-limit", "12x"});
  ExpectFailsNaming(Prep({"--generate", "sphere:100", "-o", dir_->File("s"), "--threads"}),
                    {"--threads"});
  // Found by a real-model user test, 2026-11-26: a number out of range was "not a number".
  ProcessResult r = Prep({"--generate", "sphere:100", "-o", dir_->File("s"), "--mem-limit", "16"});
  ExpectFailsNaming(r, {"--mem-limit 16: must be from 64 to 16777216 (MiB)"});
  EXPECT_EQ(r.err.find("not a number"), std::string::npos) << r.err;
  ExpectFailsNaming(Prep({"--generate", "sphere:100", "-o", dir_->File("s"), "--threads", "0"}),
                    {"--threads 0: must be from 1 to 1024"});
}

TEST_F(PrepCliTest, TargetAboveCapFails) {
  ExpectFailsNaming(Prep({"--generate", "sphere:100", "-o", dir_->File("s"), "--max-block-kb",
                          "16", "--target-block-kb", "32"}),
                    {"--target-block-kb", "--max-block-kb"});
}

// A usage error (exit 2, as for any bad option), found before anything runs.
TEST_F(PrepCliTest, UnknownGeneratorFails) {
  for (const std::string spec : {"teapot:100", "sphere:0", "sphere:x"}) {
    const ProcessResult r = Prep({"--generate", spec, "-o", dir_->File("s")});
    ExpectFailsNaming(r, {spec});
    EXPECT_EQ(r.exit_code, 2) << spec;
  }
}

TEST_F(PrepCliTest, MissingInputFails) {
  const std::string missing = dir_->File("no-such-model.obj");
  const ProcessResult r = Prep({missing, "-o", dir_->File("s")});
  ExpectFailsNaming(r, {"cannot open " + missing});
  // Found by a real-model user test, 2026-11-26: "reading X: 0 B in 0.0 s" came first.
  EXPECT_EQ(r.out.find("reading"), std::string::npos) << r.out;
  EXPECT_EQ(r.err.find("reading"), std::string::npos) << r.err;
}

TEST_F(PrepCliTest, AModelWithoutTrianglesNamesItsFile) {
  const std::string obj = dir_->File("points.obj");
  std::ofstream(obj) << "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  ExpectFailsNaming(Prep({obj, "-o", dir_->File("s"), "-q"}), {obj + ": no triangles"});
}

// What a converter leaves out or finds senseless is said, naming the place: data past the PLY
// elements its header declares, an MTL colour below 0.
TEST_F(PrepCliTest, IgnoredOrClampedInputIsReportedWithItsPlace) {
  const std::string ply = dir_->File("short.ply");
  std::ofstream(ply) << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                        "property float y\nproperty float z\nelement face 1\n"
                        "property list uchar int vertex_indices\nend_header\n"
                        "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 2 1\n";
  ProcessResult r = Prep({ply, "-o", dir_->File("a")});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find(ply + ":14: data after the elements the header declares; ignored"),
            std::string::npos) << r.err;
  const std::string obj = dir_->File("tri.obj");
  std::ofstream(obj) << "mtllib tri.mtl\nusemtl red\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  std::ofstream(dir_->File("tri.mtl")) << "Ka 1 1 1\nnewmtl red\nKd 1 -0.5 0\n";
  r = Prep({obj, "-o", dir_->File("b")});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("tri.mtl:3: Kd: a colour value below 0 (rendered as 0)"), std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("tri.mtl:1: 'Ka' before any newmtl belongs to no material; ignored"),
            std::string::npos) << r.err;
}

// Found by a real-model user test, 2026-11-26: the store keeps 63 bytes of a material name,
// so two names equal that far merged without a word (and a scene override hit both).
TEST_F(PrepCliTest, MaterialNamesTheStoreCutsAreReported) {
  const std::string red = std::string(63, 'a') + "XRED", green = std::string(63, 'a') + "YGREEN";
  const std::string obj = dir_->File("long.obj");
  std::ofstream(obj) << "mtllib long.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nusemtl " << red
                     << "\nf 1 2 3\nusemtl " << green << "\nf 2 4 3\nusemtl short\nf 1 2 4\n";
  std::ofstream(dir_->File("long.mtl")) << "newmtl " << red << "\nKd 1 0 0\nnewmtl " << green
                                        << "\nKd 0 1 0\nnewmtl short\n";
  const ProcessResult r = Prep({obj, "-o", dir_->File("s"), "-q"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const std::string mtl = dir_->File("long.mtl");
  EXPECT_NE(r.err.find(mtl + ":1: material '" + red + "' is 67 bytes long; the store keeps 63"),
            std::string::npos) << r.err;
  EXPECT_NE(r.err.find(mtl + ":3: material '" + green + "' is 69 bytes long"), std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("materials '" + green + "' and '" + red + "' become one name"),
            std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("'short'"), std::string::npos) << r.err;
}

// The summary names the store and the emitters lights.bin lists, -q or not (it is the result,
// as --stats-json's figures; -q drops the progress and information lines around it).
TEST_F(PrepCliTest, TheSummaryAndInfoShowTheEmitters) {
  const std::string box = std::string(RAYSTACK_TEST_DATA) + "/CornellBox-Original.obj";
  ProcessResult r = Prep({box, "-o", dir_->File("loud"), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("store " + dir_->File("loud")), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("2 emissive triangles"), std::string::npos) << r.out;
  // raystack-info shows what the renderer reads of each material, and the emitters listed.
  r = Info({dir_->File("loud")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("lights           2 emissive triangles (lights.bin)"), std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("Ke (17 12 4) Ni 1 d 1 illum 2"), std::string::npos) << r.out;
}

// Found by a helper converting a georeferenced scan (a 19 cm grid at UTM coordinates): floats
// there have steps of 0.5 m, every triangle fell flat, and the only word was "dropped 495
// zero-area triangles". Now prep says why and what to do; a model near the origin hears nothing.
TEST_F(PrepCliTest, AModelFarFromTheOriginForItsSizeIsWarnedOfItsLostDetail) {
  auto square = [&](const std::string& name, double at) {
    const std::string obj = dir_->File(name);
    std::ofstream(obj) << std::setprecision(17) << "v " << at << " " << at << " 0\nv "
                       << at + 3 << " " << at << " 0\nv " << at + 3 << " " << at + 3 << " 0\nv "
                       << at << " " << at + 3 << " 0\nf 1 2 3 4\n";
    return obj;
  };
  ProcessResult r = Prep({square("far.obj", 5.4e6), "-o", dir_->File("far"), "-q"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("the model is 3 across but lies 5.4e+06 from the origin, where floats (what the store keeps) have steps of 0.5: 6 steps"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("Convert it with --shift auto (or --shift 5400001.5,5400001.5,0)"),
            std::string::npos) << r.err;
  r = Prep({square("near.obj", 1000), "-o", dir_->File("near"), "-q"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find("--shift auto"), std::string::npos) << r.err;
  // --shift auto moves it before its coordinates become floats: no warning, and the summary
  // says the shift.
  r = Prep({square("far.obj", 5.4e6), "-o", dir_->File("shifted"), "--shift", "auto", "-q"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find("--shift auto"), std::string::npos) << r.err;
  EXPECT_NE(r.out.find("shift          (5400000, 5400000, 0) subtracted from every position"),
            std::string::npos) << r.out;
  ExpectFailsNaming(Prep({"--generate", "sphere:100", "-o", dir_->File("g"), "--shift", "5,5,5"}),
                    {"--shift applies to positions read from files"});
  for (const char* bad : {"1,2", "a,b,c", "1,2,3,4", "nan,0,0"})
    ExpectFailsNaming(Prep({square("far.obj", 5.4e6), "-o", dir_->File("x"), "--shift", bad}),
                      {"--shift wants auto or X,Y,Z", bad});
}

// Found by a helper converting exporters' files: vertex colours were dropped without a word,
// 2,000 materials of a missing MTL printed 2,000 warnings, and an MTL key raystack does not know
// was ignored silently.
TEST_F(PrepCliTest, WhatIsNotReadIsSaidOnceAndManyNamesAreCounted) {
  const std::string obj = dir_->File("coloured.obj");
  {
    std::ofstream out(obj);
    out << "mtllib missing.mtl\nmtllib odd.mtl\nv 0 0 0 1 0 0\nv 1 0 0 1 0 0\nv 0 1 0 1 0 0\n";
    for (int m = 0; m < 10; ++m) out << "usemtl m" << m << "\nf 1 2 3\n";
    out << "usemtl odd\nf 1 2 3\n";
  }
  std::ofstream(dir_->File("odd.mtl")) << "newmtl odd\nKd 1 0 0\nfrobnicate 2\nfrobnicate 3\n";
  const ProcessResult r = Prep({obj, "-o", dir_->File("s"), "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto count = [&](const std::string& text) {
    size_t n = 0;
    for (size_t at = r.err.find(text); at != std::string::npos; at = r.err.find(text, at + 1)) ++n;
    return n;
  };
  EXPECT_EQ(count("vertex colours ('v x y z r g b') are not read"), 1u) << r.err;
  EXPECT_EQ(count("is defined in no MTL file: it renders as the converter's default"), 8u) << r.err;
  EXPECT_EQ(count("2 more materials are defined in no MTL file"), 1u) << r.err;
  EXPECT_EQ(count("odd.mtl:3: 'frobnicate' is no MTL statement raystack knows"), 1u) << r.err;
}

// Found by a scale review: a PLY declaring more faces than a store's 32-bit triangle ids allow
// was read until the limit (~4.3 billion triangles, hours and ~190 GB of spool) before its error.
// The header's count is now warned of at once, before the vertices are read (the error stays where the limit is reached: a face with fewer than 3 corners gives no
// triangle, so the count alone proves nothing).
TEST_F(PrepCliTest, APlyDeclaringMoreFacesThanAStoreHoldsIsWarnedOfAtItsHeader) {
  const std::string ply = dir_->File("huge.ply");
  std::ofstream(ply) << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                        "property float y\nproperty float z\nelement face 5000000000\n"
                        "property list uchar int vertex_indices\nend_header\n"
                        "0 0 0\n1 0 zero\n";  // the vertices end early: the faces are never reached
  const ProcessResult r = Prep({ply, "-o", dir_->File("s")});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("huge.ply: the header declares 5000000000 faces, more than the 4294967294 "
                       "triangles the store can still take"), std::string::npos) << r.err;
  // Not also a disk warning for a model that cannot be converted anyway (a persona).
  EXPECT_EQ(r.err.find("will likely"), std::string::npos) << r.err;
}

// Found by the day's review of ear clipping: a comb-shaped face, split exactly, leaves long thin
// triangles between its few bottom corners and its many top ones; every split of them separates
// a little, so no rule stopped it: 20 such faces of 4,096 corners (a 2 MB OBJ) made 4,606
// references per triangle, a 3.2 GB store, in 165 s. Every split now draws on a budget of 32.
TEST_F(PrepCliTest, LongThinTrianglesCannotMultiplyTheStore) {
  const std::string obj = dir_->File("comb.obj");
  {
    std::ofstream out(obj);
    const int top = 2046;
    for (int face = 0; face < 2; ++face) {
      for (int i = 0; i < top; ++i) out << "v " << i << " " << (i % 2 ? 1 : 2) << " " << face * 0.1 << "\n";
      out << "v " << top - 1 << " 0 " << face * 0.1 << "\nv 0 0 " << face * 0.1 << "\n";
    }
    for (int face = 0; face < 2; ++face) {
      out << "f";
      for (int i = 1; i <= top + 2; ++i) out << " " << face * (top + 2) + i;
      out << "\n";
    }
  }
  const std::string json = dir_->File("comb.json");
  const ProcessResult r = Prep({obj, "-o", dir_->File("comb"), "--stats-json", json, "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string stats = testing::Slurp(json);
  const auto number = [&](const std::string& key) {
    const size_t at = stats.find("\"" + key + "\": ");
    return at == std::string::npos ? -1.0 : std::stod(stats.substr(at + key.size() + 4));
  };
  ASSERT_GT(number("triangles"), 0) << stats;
  EXPECT_LE(number("references") / number("triangles"), 32.0) << stats;
  EXPECT_NE(r.err.find("references reached 32 per triangle"), std::string::npos) << r.err;
}

// Float ray tracing multiplies coordinates: a model whose copies reach past +-1e18, or one
// smaller than 1e-15 across, would render wrong (overflow, underflow), so prep refuses it and
// says which way to scale. Models just inside both limits are accepted.
TEST_F(PrepCliTest, AModelOutsideTheRangeFloatTracingWorksInIsRefused) {
  auto triangle = [&](const std::string& name, const char* size) {
    const std::string obj = dir_->File(name);
    std::ofstream(obj) << "v 0 0 0\nv " << size << " 0 0\nv 0 " << size << " 0\nf 1 2 3\n";
    return obj;
  };
  ExpectFailsNaming(Prep({triangle("big.obj", "6e17"), "--replicate", "3,1,1", "-o",
                          dir_->File("a"), "-q"}),
                    {"the model's copies (--replicate) reach", "beyond +-1e18", "scale it down"});
  ExpectFailsNaming(Prep({triangle("tiny.obj", "1e-16"), "-o", dir_->File("b"), "-q"}),
                    {"the model is 1e-16 across", "scale it up"});
  for (const char* size : {"9e17", "2e-15"}) {
    const ProcessResult r = Prep({triangle("ok.obj", size), "-o", dir_->File("c"), "-q"});
    EXPECT_EQ(r.exit_code, 0) << size << ": " << r.err;
  }
}

// Two converters writing one store shared its temporaries and left it corrupt, each saying
// it had succeeded or failing with "cannot rename into place". The store's folder is locked
// while it is written: a second writer is refused at once, naming the folder.
TEST_F(PrepCliTest, TwoWritersOfOneStoreAreRefused) {
  const std::string out = dir_->File("shared");
  Expected<std::unique_ptr<store::StoreWriter>> writing = store::StoreWriter::Create(out);
  ASSERT_TRUE(writing.ok()) << writing.status().message();
  ExpectFailsNaming(Prep({"--generate", "sphere:1000", "-o", out, "-q"}),
                    {out + ": another raystack-prep is writing this store now"});
  writing->reset();  // that writer gone (as when its process ends), the store can be written
  const ProcessResult r = Prep({"--generate", "sphere:1000", "-o", out, "-q"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(Info({out, "--verify"}).exit_code, 0);
}

// Found by a real-model user test, 2026-11-26: a prep failing on a full disk said so, but left
// OUT/blocks.bin.tmp (all the free space) and OUT/.lock behind. RLIMIT_FSIZE stands in for the
// full disk (SIGXFSZ ignored, a write past it fails with EFBIG as on ENOSPC).
TEST_F(PrepCliTest, AFailedWriteRemovesThePartialStore) {
  namespace fs = std::filesystem;
  auto small_files = [] {
    std::signal(SIGXFSZ, SIG_IGN);
    const rlimit limit{256 << 10, 256 << 10};
    setrlimit(RLIMIT_FSIZE, &limit);
  };
  auto prep = [&](const std::string& out) {
    return RunProcess({kPrepBinary, "--generate", "sphere:400000", "-o", out, "--temp-dir",
                       dir_->path(), "-q"}, dir_->path(), small_files);
  };
  const std::string fresh = dir_->File("fresh");  // made by the failing prep: all of it goes
  ProcessResult r = prep(fresh);
  ExpectFailsNaming(r, {"write failed (disk full?)"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_FALSE(fs::exists(fresh)) << r.err;

  // A store that was there before keeps its lock file (another prep may have it open) and
  // its other files; only the temporaries go.
  const std::string old = dir_->File("old");
  ASSERT_EQ(Prep({"--generate", "sphere:1000", "-o", old, "-q"}).exit_code, 0);
  r = prep(old);
  ExpectFailsNaming(r, {"write failed (disk full?)"});
  for (const fs::directory_entry& e : fs::directory_iterator(old))
    EXPECT_NE(e.path().extension(), ".tmp") << e.path();
  EXPECT_TRUE(fs::exists(old + "/" + store::kLockFile));
  EXPECT_TRUE(fs::exists(old + "/" + store::kOctreeFile));
  // And it is still a store, whole: the new one would have replaced it only once complete (a
  // user found it gone, its index.bin removed as the failed prep started).
  EXPECT_EQ(Info({old, "--verify"}).exit_code, 0);

  // Named through a folder the prep makes on the way ("old/x/.."), it is still the old store
  // (a review found its files deleted).
  r = prep(old + "/x/..");
  ExpectFailsNaming(r, {"write failed (disk full?)"});
  EXPECT_TRUE(fs::exists(old + "/" + store::kLockFile)) << r.err;
  EXPECT_TRUE(fs::exists(old + "/" + store::kOctreeFile)) << r.err;
  EXPECT_TRUE(fs::exists(old + "/" + store::kBlocksFile)) << r.err;
}

// Found by the scale review: a disk too small for the bucket files or the store was found when
// it filled, hours into a large conversion. After the model is read, the build's writes are
// estimated and checked against the free space, before the first bucket is written: a
// warning naming the folder (the run goes on: the figures are estimates). 6.4 M triangles
// (100,000 x 64 copies, read in a moment) on a 48 MB tmpfs, as the temporary folder or the store.
TEST_F(PrepCliTest, ADiskTooSmallForTheBuildIsSaidBeforeItIsWritten) {
  raystack::testing::SmallTmpfs small(dir_->File("small"), "size=48m");
  if (small.path.empty()) GTEST_SKIP() << small.why;
  const std::vector<std::string> model = {"--generate", "sphere:100000", "--replicate", "4,4,4",
                                          "--mem-limit", "64"};
  std::vector<std::string> args = model;
  args.insert(args.end(), {"-o", dir_->File("a"), "--temp-dir", small.path});
  ProcessResult r = Prep(args);
  ExpectFailsNaming(r, {"write failed (disk full?)"});
  const size_t warned = r.err.find("the build will likely write about 0.3");
  EXPECT_NE(warned, std::string::npos) << r.err;
  EXPECT_NE(r.err.find("GB of temporary files in " + small.path + ", whose file system has 0.0"),
            std::string::npos) << r.err;
  EXPECT_NE(r.err.find("or give --temp-dir on a larger disk"), std::string::npos) << r.err;
  EXPECT_LT(warned, r.err.find("partitioning")) << "before the first bucket: " << r.err;

  args = model;
  args.insert(args.end(), {"-o", small.path + "/store", "--mem-limit", "2048"});
  r = Prep(args);
  ExpectFailsNaming(r, {"write failed (disk full?)"});
  EXPECT_NE(r.err.find("the store will likely take about 0.1"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("GB in " + small.path + "/store, whose file system has 0.0"),
            std::string::npos) << r.err;

  // A PLY is checked at its header, before its body is read (hours for a large scan): 4 M faces
  // declared (the body is broken: the read never gets far).
  const std::string ply = dir_->File("scan.ply");
  std::ofstream(ply) << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                        "property float y\nproperty float z\nelement face 4000000\n"
                        "property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 zero\n";
  r = Prep({ply, "-o", dir_->File("c"), "--temp-dir", small.path, "--mem-limit", "64"});
  EXPECT_NE(r.exit_code, 0);
  const size_t early = r.err.find("GB of temporary files in " + small.path);
  EXPECT_NE(early, std::string::npos) << r.err;
  EXPECT_LT(early, r.err.find("scan.ply:6")) << "before the body's error: " << r.err;

  // An OBJ declares nothing: its size does, at kObjMostBytesPerTriangle (512) bytes a triangle
  // at most. 1 GB (sparse: no disk) holds at least 2 M triangles, too many for the folder; said,
  // as the least it needs, before the body's error, as for the PLY.
  const std::string obj = dir_->File("scan.obj");
  std::ofstream(obj) << "v 0 0 0\nv 1 0 zero\n";
  std::filesystem::resize_file(obj, uint64_t{1} << 30);
  r = Prep({obj, "-o", dir_->File("o"), "--temp-dir", small.path, "--mem-limit", "64"});
  EXPECT_NE(r.exit_code, 0);
  const size_t said = r.err.find("GB of temporary files in " + small.path);
  EXPECT_NE(said, std::string::npos) << r.err;
  EXPECT_NE(r.err.find("the build will write at least "), std::string::npos) << r.err;
  EXPECT_LT(said, r.err.find("scan.obj:2")) << "before the body's error: " << r.err;

  // A header's normals count: 300,000 faces with them spool at 104 bytes each, not 44 (a review:
  // no warning at the header, then a full disk after the read).
  std::ofstream(dir_->File("normals.ply"))
      << "ply\nformat ascii 1.0\nelement vertex 150000\nproperty float x\nproperty float y\n"
         "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
         "element face 300000\nproperty list uchar int vertex_indices\nend_header\n0 0 zero\n";
  r = Prep({dir_->File("normals.ply"), "-o", dir_->File("n"), "--temp-dir", small.path, "--mem-limit", "64"});
  EXPECT_NE(r.err.find("GB of temporary files in " + small.path), std::string::npos) << r.err;

  // Room for the bucket files or the store, on one file system, but not both at once: no word
  // (the buckets are deleted as the store is written; a persona's false alarm counted both).
  r = Prep({"--generate", "sphere:100000", "--replicate", "2,2,2", "--mem-limit", "64", "-o",
            small.path + "/both", "--temp-dir", small.path});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find("will likely"), std::string::npos) << r.err;

  // Room enough (the test's folder): no word.
  args = model;
  args.insert(args.end(), {"-o", dir_->File("b"), "--temp-dir", dir_->path()});
  r = Prep(args);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find("will likely"), std::string::npos) << r.err;
}

// Found by a converter persona: a gzipped PLY (as scans are often shared) was an "unknown model
// format", without a word of the compression.
TEST_F(PrepCliTest, AGzippedModelIsNamedAsSuch) {
  for (const char* name : {"scan.ply.gz", "scan.obj"}) {  // (whatever it is called)
    const std::string gz = dir_->File(name);
    std::ofstream(gz, std::ios::binary) << std::string("\x1f\x8b\x08\x00rest", 8);
    const ProcessResult r = Prep({gz, "-o", dir_->File("s")});
    ExpectFailsNaming(r, {std::string(name) + ": compressed with gzip: decompress it first (gunzip -k"});
  }
}

// Found by a converter persona: after a conversion into a store was killed (kill -9: no clean
// up), raystack-info reported the old store complete without a word of the 345 MB of .tmp files
// beside it.
TEST_F(PrepCliTest, InfoNotesWhatAKilledConversionLeftBesideTheStore) {
  ASSERT_EQ(Prep({"--generate", "sphere:1000", "-o", dir_->File("s"), "-q"}).exit_code, 0);
  EXPECT_EQ(Info({dir_->File("s")}).out.find(".tmp files"), std::string::npos);
  std::ofstream(dir_->File("s/blocks.bin.tmp")) << std::string(2'500'000, 'x');
  ProcessResult r = Info({dir_->File("s")});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("2.5 MB of .tmp files beside it, left by an interrupted conversion"),
            std::string::npos) << r.out;
  // While a conversion runs, its files are not leftovers (a review: "0.0 MB ... interrupted").
  {
    Expected<std::unique_ptr<store::StoreWriter>> writing = store::StoreWriter::Create(dir_->File("s"));
    ASSERT_TRUE(writing.ok()) << writing.status().message();
    r = Info({dir_->File("s")});
    EXPECT_NE(r.out.find("a conversion is writing into this store now"), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find("left by an interrupted conversion"), std::string::npos) << r.out;
    (*writing)->Abandon();
  }
}

// Found by a hostile-input review: 65,535 'usemtl' names no MTL defines were "more than 65534
// materials in the model's MTL libraries", naming no file (the model had no library at all).
TEST_F(PrepCliTest, TooManyMaterialsNameTheFileAndCountUndefinedNames) {
  const std::string obj = dir_->File("names.obj");
  {
    std::ofstream f(obj);
    f << "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    for (int i = 0; i < 65535; ++i) f << "usemtl m" << i << "\nf 1 2 3\n";
  }
  const ProcessResult r = Prep({obj, "-o", dir_->File("names"), "-q"});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find(obj + ": more than 65534 materials used by the faces (the store "
                       "format's limit)"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("each 'usemtl' name that no MTL defines counts as one"),
            std::string::npos) << r.err;
}

// Left alone by the hostile-input review, then done: an MTL library of 70,000 materials of which
// the model uses two was refused as too many. The store keeps what the faces use (data the
// model does not need is never stored), numbered in order of first use.
TEST_F(PrepCliTest, OnlyTheMaterialsTheFacesUseAreStored) {
  const std::string obj = dir_->File("lib.obj");
  {
    std::ofstream mtl(dir_->File("lib.mtl"));
    for (int i = 0; i < 70000; ++i) mtl << "newmtl m" << i << "\nKd 0." << i % 10 << " 0 0\n";
    std::ofstream(obj) << "mtllib lib.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
                       << "usemtl m69999\nf 1 2 3\nusemtl m5\nf 2 4 3\nusemtl m69999\nf 1 2 4\n";
  }
  ProcessResult r = Prep({obj, "-o", dir_->File("lib")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("2 of the model's 70000 materials are used by its faces: only those are "
                       "stored"), std::string::npos) << r.err;
  Expected<std::unique_ptr<store::StoreReader>> s = store::StoreReader::Open(dir_->File("lib"));
  ASSERT_TRUE(s.ok()) << s.status().message();
  ASSERT_EQ((*s)->materials().size(), 2u);
  EXPECT_STREQ((*s)->materials()[0].name, "m69999");
  EXPECT_EQ((*s)->materials()[0].kd[0], 0.9f);
  EXPECT_STREQ((*s)->materials()[1].name, "m5");
  EXPECT_EQ((*s)->materials()[1].kd[0], 0.5f);
  // Each face keeps its own material through the renumbering: triangles 0 and 2 use m69999.
  std::vector<uint8_t> stored;
  store::AlignedBuffer scratch, raw;
  ASSERT_EQ((*s)->blocks().size(), 1u);
  Expected<store::BlockView> v = (*s)->Load(0, &stored, &scratch, &raw);
  ASSERT_TRUE(v.ok()) << v.status().message();
  ASSERT_EQ(v->triangle_count(), 3u);
  for (uint32_t t = 0; t < v->triangle_count(); ++t)
    EXPECT_EQ(v->Material(t), v->TriangleId(t) == 1 ? 1u : 0u) << "triangle " << v->TriangleId(t);
  // A model whose faces use every material it defines says nothing of it.
  r = Prep({std::string(RAYSTACK_TEST_DATA) + "/CornellBox-Original.obj", "-o", dir_->File("box")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find("materials are used by its faces"), std::string::npos) << r.err;
}

// Found by a pipeline review: --stats-json on a full disk left a 0-byte file and /dev/full
// gave exit 0 (the figures lost without a word). Now each is an error (the store is written),
// and an earlier file is kept whole rather than emptied.
TEST_F(PrepCliTest, StatsJsonThatCannotBeWrittenIsAnErrorAndKeepsTheEarlierFile) {
  ProcessResult r = Prep({"--generate", "sphere:100", "-o", dir_->File("s"), "-q",
                          "--stats-json", "/dev/full"});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("--stats-json /dev/full: cannot write: No space left on device (the "
                       "store is written)"), std::string::npos) << r.err;
  // A pipe is written in place (nothing renamed over /dev/stdout).
  r = Prep({"--generate", "sphere:100", "-o", dir_->File("s"), "-q", "--stats-json", "/dev/stdout"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("{\"triangles\": 108,"), std::string::npos) << r.out;
  // /dev/stdout sent to a file is that file, written in place: the summary stays in it (the
  // day's review: a rename put the JSON in its place).
  r = RunProcess({"/bin/sh", "-c", std::string(kPrepBinary) + " --generate sphere:100 -o " +
                  dir_->File("s") + " --stats-json /dev/stdout > " + dir_->File("out.log")},
                 dir_->path());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const std::string log = testing::Slurp(dir_->File("out.log"));
  EXPECT_NE(log.find("store " + dir_->File("s")), std::string::npos) << log;
  EXPECT_NE(log.find("{\"triangles\": 108,"), std::string::npos) << log;
  // A link, dangling too, stays a link: the file it names is written.
  std::filesystem::create_symlink("named.json", dir_->File("link.json"));
  r = Prep({"--generate", "sphere:100", "-o", dir_->File("s"), "-q", "--stats-json",
            dir_->File("link.json")});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(std::filesystem::is_symlink(dir_->File("link.json")));
  EXPECT_EQ(testing::Slurp(dir_->File("named.json")).rfind("{\"triangles\": 108,", 0), 0u);
  raystack::testing::SmallTmpfs small(dir_->File("small"), "size=8k");
  if (small.path.empty()) GTEST_SKIP() << small.why;
  const std::string stats = small.path + "/stats.json";
  std::ofstream(stats) << "{\"earlier\": 1}\n";
  std::ofstream(small.path + "/filler") << std::string(4096, 'x');  // the rest of the 8 KB
  r = Prep({"--generate", "sphere:100", "-o", dir_->File("s"), "-q", "--stats-json", stats});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("--stats-json " + stats + ": cannot write: No space left on device"),
            std::string::npos) << r.err;
  EXPECT_EQ(testing::Slurp(stats), "{\"earlier\": 1}\n");
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(small.path),
                          std::filesystem::directory_iterator()), 2) << "a temporary is left";
}

// Found by a pipeline review: raystack-info's report to a full disk (or /dev/full) was lost
// with exit 0, as were --version's line and prep's summary. And with the standard output
// closed (`>&-`), the next file opened would take its number: printing must not reach it.
TEST_F(PrepCliTest, AReportThatCannotBeWrittenIsAnError) {
  ASSERT_EQ(Prep({"--generate", "sphere:100", "-o", dir_->File("s"), "-q"}).exit_code, 0);
  const auto shell = [&](const std::string& command) {
    return RunProcess({"/bin/sh", "-c", command}, dir_->path());
  };
  ProcessResult r = shell(std::string(kInfoBinary) + " " + dir_->File("s") + " > /dev/full");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("raystack-info: cannot write to the standard output: No space left on "
                       "device"), std::string::npos) << r.err;
  r = shell(std::string(kPrepBinary) + " --version > /dev/full");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_NE(r.err.find("raystack-prep: cannot write to the standard output"), std::string::npos)
      << r.err;
  r = shell(std::string(kPrepBinary) + " --generate sphere:100 -o " + dir_->File("t") +
            " --stats-json " + dir_->File("t.json") + " >&-");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(testing::Slurp(dir_->File("t.json")).rfind("{\"triangles\": 108,", 0), 0u);
  EXPECT_EQ(Info({dir_->File("t"), "--verify"}).exit_code, 0);
}

// Found by a converter persona: --stats-json inside the store worked once, and the next
// conversion into that store refused the folder ("holds other files ('stats.json')").
TEST_F(PrepCliTest, StatsInsideTheStoreAreRefusedUpFront) {
  const ProcessResult r = Prep({"--generate", "sphere:1000", "-o", dir_->File("s") + "/",
                                "--stats-json", dir_->File("s/./stats.json")});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("is the store " + dir_->File("s") + "/ or inside it"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("(e.g. " + dir_->File("s.json") + ")"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir_->File("s")));
  // The store folder itself (a review: converted the whole model, then "Is a directory").
  EXPECT_EQ(Prep({"--generate", "sphere:1000", "-o", dir_->File("s"), "--stats-json", dir_->File("s")}).exit_code, 2);
  EXPECT_FALSE(std::filesystem::exists(dir_->File("s")));
  // Any other folder (a hostile-input review: refused after the whole conversion).
  std::filesystem::create_directories(dir_->File("figures"));
  const ProcessResult folder = Prep({"--generate", "sphere:1000", "-o", dir_->File("s"),
                                     "--stats-json", dir_->File("figures")});
  EXPECT_EQ(folder.exit_code, 2) << folder.err;
  EXPECT_NE(folder.err.find("--stats-json " + dir_->File("figures") + " is a folder"), std::string::npos)
      << folder.err;
  EXPECT_FALSE(std::filesystem::exists(dir_->File("s")));
}

// Found by a converter persona: each encoding thread holds ~150 KB of scratch, so --threads 1024
// under --mem-limit 64 peaked at 159-262 MB. The encoders are bounded by the budget, and it says so.
TEST_F(PrepCliTest, ThreadsBeyondTheMemoryLimitAreSaidAndBounded) {
  const ProcessResult r = Prep({"--generate", "sphere:400000", "--replicate", "2,2,2", "--mem-limit",
                                "64", "--threads", "1024", "-o", dir_->File("s")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("--threads 1024: --mem-limit 64 leaves room for 36 encoding threads"),
            std::string::npos) << r.err;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.out, m, std::regex("peak RSS ([0-9]+) MiB"))) << r.out;
  EXPECT_LE(std::stoi(m[1]), 64) << r.out;
}

// Ctrl-C during a conversion that replaces a store: the old store stays whole, the new one's
// temporaries and the work folder (bucket files) are removed, and the prep says so; it used to
// end silently, leaving a blocks.bin.tmp and gigabytes of bucket files, the old store unusable.
// A closed terminal (SIGHUP) too: it left 944 MB of bucket files (a pipeline review).
TEST_F(PrepCliTest, AnInterruptedPrepLeavesTheOldStoreWholeAndNoTemporaries) {
  for (const int signal : {SIGINT, SIGHUP}) {
    SCOPED_TRACE(signal);
    ExpectAnInterruptLeavesTheOldStoreWhole(signal);
  }
}

void PrepCliTest::ExpectAnInterruptLeavesTheOldStoreWhole(int signal) {
  namespace fs = std::filesystem;
  const std::string old = dir_->File("old"), temp = dir_->File("temp");
  fs::remove_all(old);
  fs::remove_all(temp);
  fs::create_directory(temp);
  ASSERT_EQ(Prep({"--generate", "sphere:1000", "-o", old, "-q"}).exit_code, 0);
  // Large enough to be still converting when interrupted (it would take a minute).
  master::preview::testing::BackgroundProcess prep(
      {kPrepBinary, "--generate", "spheres:40000000", "--mem-limit", "256", "-o", old,
       "--temp-dir", temp}, dir_->path());
  // Interrupted once the store is being written and bucket files fill the work folder (its
  // threads delete them as they go: a review found the clean-up stopping at the first one gone).
  const auto buckets = [&] {
    std::error_code ec;
    for (const fs::directory_entry& work : fs::directory_iterator(temp, ec))
      for (const fs::directory_entry& f : fs::directory_iterator(work.path(), ec))
        if (f.path().filename().string().starts_with("bucket-")) return true;
    return false;
  };
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::minutes(5);
  while (!(fs::exists(old + "/" + store::kBlocksFile + ".tmp") && buckets()) &&
         std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  ASSERT_TRUE(fs::exists(old + "/" + store::kBlocksFile + ".tmp")) << prep.err();
  prep.Signal(signal);
  EXPECT_EQ(prep.Wait(), 128 + signal) << prep.err();
  EXPECT_NE(prep.err().find(std::string("raystack-prep: interrupted (") + InterruptName(signal) +
                            "): " + old + " is as it was"),
            std::string::npos) << prep.err();
  for (const fs::directory_entry& e : fs::directory_iterator(old))
    EXPECT_NE(e.path().extension(), ".tmp") << e.path();
  EXPECT_TRUE(fs::is_empty(temp)) << "the work folder is left";
  const ProcessResult info = Info({old, "--verify"});
  EXPECT_EQ(info.exit_code, 0) << info.err;
  EXPECT_NE(info.out.find("triangles"), std::string::npos);
}

// Found by a user with a model too big for RAM: a destination that cannot be written, a typo in
// the last of several inputs and a --stats-json that cannot be written were found only after
// the models were read (or the store written); now before anything is read.
TEST_F(PrepCliTest, WhatCannotBeWrittenOrReadIsFoundBeforeTheModelIsRead) {
  const std::string model = dir_->File("m.obj");
  std::ofstream(model) << "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
  std::ofstream(dir_->File("afile")) << "not a folder";
  ExpectFailsNaming(Prep({model, "-o", dir_->File("afile") + "/store", "-q"}),
                    {"afile/store: cannot create directory:", "afile is not a folder"});
  ExpectFailsNaming(Prep({model, dir_->File("typo.obj"), "-o", dir_->File("s"), "-q"}),
                    {"cannot open " + dir_->File("typo.obj")});
  ExpectFailsNaming(Prep({model, "-o", dir_->File("s"), "-q", "--stats-json", dir_->File("none/x.json")}),
                    {"--stats-json " + dir_->File("none/x.json") + ": cannot write in"});
  EXPECT_FALSE(std::filesystem::exists(dir_->File("s"))) << "nothing is written before the checks";
}

// Progress in bytes read as "33.83M B" (a user's report); now "33.83 MB".
TEST_F(PrepCliTest, ProgressInBytesReadsAsMegabytes) {
  const std::string model = dir_->File("big.obj");
  {
    std::ofstream out(model);
    for (int i = 0; i < 60000; ++i) out << "v " << i << " 0.000001 " << i % 7 << "\n";
    for (int i = 1; i + 2 <= 60000; i += 3) out << "f " << i << " " << i + 1 << " " << i + 2 << "\n";
  }
  const ProcessResult r = Prep({model, "-o", dir_->File("s")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(std::regex_search(r.err, std::regex("reading .*big\\.obj: [0-9.]+ MB in [0-9.]+ s \\([0-9.]+ [kMG]?B/s\\)")))
      << r.err;
  EXPECT_EQ(r.err.find("M B"), std::string::npos) << r.err;
}

// An interrupt's clean-up that comes while the writer writes its last files: the writer must
// then not swap (it removed the old index, and the renames failed: the old store was left
// without one, a review found).
TEST_F(PrepCliTest, AStoreAbandonedBeforeItsSwapKeepsTheOldOne) {
  const std::string out = dir_->File("kept");
  ASSERT_EQ(Prep({"--generate", "sphere:1000", "-o", out, "-q"}).exit_code, 0);
  Expected<std::unique_ptr<store::StoreWriter>> writer = store::StoreWriter::Create(out);
  ASSERT_TRUE(writer.ok()) << writer.status().message();
  (*writer)->Abandon();
  const Status finished = (*writer)->Finish(store::StoreSummary{}, {}, {});
  EXPECT_FALSE(finished.ok());
  writer->reset();
  const ProcessResult info = Info({out, "--verify"});
  EXPECT_EQ(info.exit_code, 0) << info.err;
}

// A folder with a conversion's temporaries and no index is named as such, not as empty.
TEST_F(PrepCliTest, AStoreBeingWrittenIsNamedAsSuch) {
  const std::string out = dir_->File("half");
  std::filesystem::create_directory(out);
  std::ofstream(out + "/blocks.bin.tmp") << "partial";
  ExpectFailsNaming(Info({out}), {"raystack-prep is writing one there (or was interrupted"});
}

// A killed prep leaves its work folder (bucket files: up to gigabytes); the next prep with the
// same temporary folder removes those whose owner lock no process holds, and nothing else: not
// a live prep's (whatever its process id says: it may run in another PID namespace), not a
// folder of that name without an owner file (a user's), not another machine's.
TEST_F(PrepCliTest, WorkFoldersOfKilledPrepsAreRemoved) {
  namespace fs = std::filesystem;
  const std::string temp = dir_->File("temp");
  fs::create_directory(temp);
  const std::string own = "raystack-prep-" + HostName() + "-";
  const std::string gone = own + "4242-a1B2c3";  // its owner file unlocked: a killed prep's
  const std::string live = own + "4243-a1B2c3";  // locked below, as a live prep holds it
  const std::vector<std::string> kept = {live, own + "4244-a1B2c3" /* no owner file */,
                                         "raystack-prep-elsewhere-4242-a1B2c3",
                                         own + "4242-short", "other"};
  for (const std::string& name : kept) fs::create_directory(temp + "/" + name);
  fs::create_directory(temp + "/" + gone);
  for (const std::string& name : {gone, live, std::string("raystack-prep-elsewhere-4242-a1B2c3")})
    std::ofstream(temp + "/" + name + "/" + TempDir::kOwnerFile);
  std::ofstream(temp + "/" + gone + "/bucket-0") << "bytes";
  int held = -1;
  std::string error;
  ASSERT_EQ(TryLockFile(temp + "/" + live + "/" + TempDir::kOwnerFile, false, &held, &error),
            LockResult::kLocked) << error;
  const ProcessResult r = Prep({"--generate", "sphere:1000", "--temp-dir", temp, "-o", dir_->File("s")});
  ::close(held);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(fs::exists(temp + "/" + gone));
  EXPECT_NE(r.err.find("removed 1 work folder left by interrupted runs"), std::string::npos) << r.err;
  for (const std::string& name : kept) EXPECT_TRUE(fs::exists(temp + "/" + name)) << name;
}

TEST_F(PrepCliTest, MalformedObjNamesFileAndLine) {
  const std::string obj = dir_->File("broken.obj");
  std::ofstream(obj) << "# three vertices, then a face that uses a fourth\n"
                        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n";
  const ProcessResult r = Prep({obj, "-o", dir_->File("s"), "-q"});
  ExpectFailsNaming(r, {obj, "6"});
  // The line number appears as a line reference, not by accident inside another number.
  EXPECT_TRUE(std::regex_search(r.err, std::regex("broken\\.obj[:( ]+(line )?6\\b"))) << r.err;
}

TEST_F(PrepCliTest, GoodRunPrintsStatisticsAndVerifies) {
  const std::string store = dir_->File("store");
  const std::string json = dir_->File("stats.json");
  const ProcessResult r = Prep({"--generate", "spheres:20000", "-o", store, "--target-block-kb",
                                "8", "--max-block-kb", "32", "--threads", "2", "--temp-dir",
                                dir_->path(), "--stats-json", json, "-q"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* word : {"triangles", "blocks", "compression", "octree", "peak RSS"})
    EXPECT_NE(r.out.find(word), std::string::npos) << "no '" << word << "' in: " << r.out;
  const std::string stats = testing::Slurp(json);
  EXPECT_NE(stats.find("\"triangles\":"), std::string::npos) << stats;
  EXPECT_NE(stats.find("\"blocks\":"), std::string::npos) << stats;

  const ProcessResult info = Info({store, "--verify"});
  EXPECT_EQ(info.exit_code, 0) << info.err;
  for (const char* word : {"format version", "blocks", "bytes/triangle", "compression",
                           "histogram", "all "})
    EXPECT_NE(info.out.find(word), std::string::npos) << "no '" << word << "' in: " << info.out;
  EXPECT_TRUE(std::regex_search(info.out, std::regex("KB +[0-9]+ #"))) << "no histogram bars";
}

// Found by a real-model user test, 2026-11-26: -q kept the information lines of the octree
// builder ("[raystack info prep] partitioning ..."); render -q silences them, and so does prep.
TEST_F(PrepCliTest, QuietPrintsNoInformationLines) {
  const std::vector<std::string> args = {"--generate", "spheres:200000", "-o", dir_->File("s"),
                                         "--mem-limit", "64", "--temp-dir", dir_->path()};
  ProcessResult r = Prep(args);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_NE(r.err.find("[raystack info prep] partitioning"), std::string::npos)
      << "the model no longer makes prep partition on disk; make it larger: " << r.err;
  std::vector<std::string> quiet = args;
  quiet.push_back("-q");
  r = Prep(quiet);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find("[raystack info"), std::string::npos) << r.err;
}

// Every damaged block is named, not only the first (a user's store had three), and counted.
TEST_F(PrepCliTest, VerifyNamesEveryDamagedBlock) {
  const std::string store = dir_->File("store");
  ASSERT_EQ(Prep({"--generate", "sphere:20000", "-o", store, "--target-block-kb", "8", "-q"})
                .exit_code,
            0);
  std::vector<uint32_t> victims;
  std::vector<uint64_t> offsets;
  uint32_t blocks = 0;
  {
    Expected<std::unique_ptr<store::StoreReader>> s = store::StoreReader::Open(store);
    ASSERT_TRUE(s.ok()) << s.status().message();
    blocks = static_cast<uint32_t>((*s)->blocks().size());
    ASSERT_GT(blocks, 4u);
    for (uint32_t victim : {blocks / 4, blocks / 2, blocks - 1}) {
      const store::BlockEntry& e = (*s)->blocks()[victim];
      victims.push_back(victim);
      offsets.push_back(e.offset + e.stored_bytes / 2);
    }
  }
  {
    std::fstream f(store + "/blocks.bin", std::ios::in | std::ios::out | std::ios::binary);
    for (const uint64_t offset : offsets) {
      f.seekg(static_cast<std::streamoff>(offset));
      char c = 0;
      f.read(&c, 1);
      c = static_cast<char>(c ^ 0x5a);
      f.seekp(static_cast<std::streamoff>(offset));
      f.write(&c, 1);
    }
    ASSERT_TRUE(f.good());
  }
  // Without --verify the index is intact, so it still opens.
  EXPECT_EQ(Info({store}).exit_code, 0);
  const ProcessResult r = Info({store, "--verify"});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  for (const uint32_t victim : victims)
    EXPECT_TRUE(std::regex_search(r.err, std::regex("block " + std::to_string(victim) + "\\b")))
        << victim << ": " << r.err;
  EXPECT_NE(r.err.find("3 of " + std::to_string(blocks) + " blocks are damaged"), std::string::npos)
      << r.err;
}

TEST_F(PrepCliTest, InfoOnMissingStoreFails) {
  ExpectFailsNaming(Info({dir_->File("nothing-here")}), {"nothing-here"});
}

}  // namespace
}  // namespace raystack::prep
