// "Bounded memory, really": raystack-prep converts a model several times larger than its
// memory budget inside a real cgroup-v1 memory cap (anonymous memory and page cache both
// count), and must finish without being OOM-killed, with a store that verifies.

#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <regex>

#include "common/base/temp_dir.h"
#include "tests/prep/run_process.h"
#include "tests/support/memory_cgroup.h"

namespace raystack::prep {
namespace {

using testing::kInfoBinary;
using testing::kPrepBinary;
using testing::ProcessResult;
using testing::RunProcess;
using raystack::testing::MemoryCgroup;
using raystack::testing::ReadKey;
using raystack::testing::ReadValue;

constexpr uint64_t kCapBytes = 320ull << 20;
constexpr int kMemLimitMb = 256;
// 2 M triangles on a 3x2x2 grid: 24 M triangles, 864 MB of raw positions alone.
constexpr uint64_t kSourceTriangles = 2000000;
constexpr int kCopies = 3 * 2 * 2;

TEST(MemoryCap, ConvertsAModelLargerThanTheCap) {
  std::string why;
  const std::unique_ptr<MemoryCgroup> group = MemoryCgroup::CreateOwnChild("raystack-memcap", &why);
  if (!group) GTEST_SKIP() << "no cgroup-v1 memory cap possible: " << why;
  ASSERT_TRUE(group->Limit(kCapBytes)) << "cannot set the limit of " << group->path();
  // The model is bigger than the cap: it cannot simply be held in memory.
  ASSERT_GT(kSourceTriangles * kCopies * 36, kCapBytes);

  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok()) << dir.status().message();
  const std::string store = dir->File("store");
  const auto start = std::chrono::steady_clock::now();
  const ProcessResult r = RunProcess(
      {kPrepBinary, "--generate", "sphere:" + std::to_string(kSourceTriangles), "--replicate",
       "3,2,2", "--mem-limit", std::to_string(kMemLimitMb), "-q", "--temp-dir", dir->path(),
       "-o", store},
      dir->path(), group->Joiner());
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  const uint64_t max_usage = ReadValue(group->File("memory.max_usage_in_bytes"));
  const uint64_t failcnt = ReadValue(group->File("memory.failcnt"));
  const int64_t oom_kills = ReadKey(group->File("memory.oom_control"), "oom_kill");
  ::testing::Test::RecordProperty("cgroup_limit_bytes", std::to_string(kCapBytes));
  ::testing::Test::RecordProperty("cgroup_max_usage_bytes", std::to_string(max_usage));
  ::testing::Test::RecordProperty("cgroup_failcnt", std::to_string(failcnt));
  ::testing::Test::RecordProperty("wall_seconds", std::to_string(seconds));
  std::printf("memory cap: limit %llu MB, peak usage %.1f MB, failcnt %llu, oom kills %lld, "
              "%.1f s wall, %llu triangles\n",
              static_cast<unsigned long long>(kCapBytes >> 20), max_usage / 1048576.0,
              static_cast<unsigned long long>(failcnt), static_cast<long long>(oom_kills),
              seconds, static_cast<unsigned long long>(kSourceTriangles * kCopies));

  ASSERT_NE(r.exit_code, 125) << "the child could not join " << group->path();
  EXPECT_EQ(r.signal, 0) << "raystack-prep was killed by signal " << r.signal
                         << " (SIGKILL = the OOM killer); stderr: " << r.err;
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // Its own peak RSS (anonymous memory; the cgroup figure also counts page cache) keeps to
  // --mem-limit.
  std::smatch rss;
  ASSERT_TRUE(std::regex_search(r.out, rss, std::regex("peak RSS ([0-9]+) MiB"))) << r.out;
  const int peak_rss_mb = std::stoi(rss[1].str());
  ::testing::Test::RecordProperty("prep_peak_rss_mb", std::to_string(peak_rss_mb));
  std::printf("memory cap: raystack-prep peak RSS %d MiB (--mem-limit %d)\n", peak_rss_mb, kMemLimitMb);
  EXPECT_LE(peak_rss_mb, kMemLimitMb);
  EXPECT_LE(oom_kills, 0) << "the OOM killer fired in " << group->path();
  EXPECT_GT(max_usage, 0u) << "nothing was charged to the group: the run was not capped";
  EXPECT_LE(max_usage, kCapBytes);

  const ProcessResult info = RunProcess({kInfoBinary, store, "--verify"}, dir->path());
  EXPECT_EQ(info.exit_code, 0) << info.err;
  // About 2 M triangles per copy (the cube-sphere rounds N to its grid).
  std::smatch m;
  ASSERT_TRUE(std::regex_search(info.out, m, std::regex("triangles +([0-9]+)"))) << info.out;
  const uint64_t stored = std::stoull(m[1].str());
  EXPECT_EQ(stored % kCopies, 0u);
  EXPECT_GT(stored, kSourceTriangles * kCopies * 9 / 10);
  EXPECT_NE(info.out.find("all "), std::string::npos) << info.out;
}

// A --mem-limit above the cap would end in the OOM killer without a word: prep says so first
// (and, at a budget that fits, says nothing).
TEST(MemoryCap, ABudgetAboveTheCapIsWarnedAbout) {
  std::string why;
  const std::unique_ptr<MemoryCgroup> group = MemoryCgroup::CreateOwnChild("raystack-memwarn", &why);
  if (!group) GTEST_SKIP() << "no cgroup-v1 memory cap possible: " << why;
  ASSERT_TRUE(group->Limit(kCapBytes)) << "cannot set the limit of " << group->path();
  Expected<TempDir> dir = TempDir::Create();
  ASSERT_TRUE(dir.ok()) << dir.status().message();
  for (const int mb : {1024, 128}) {
    const ProcessResult r = RunProcess({kPrepBinary, "--generate", "sphere:1000", "--mem-limit",
                                        std::to_string(mb), "-q", "-o", dir->File("s")},
                                       dir->path(), group->Joiner());
    EXPECT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(r.err.find("--mem-limit " + std::to_string(mb) + " MiB is above the") !=
                  std::string::npos, mb == 1024) << mb << ": " << r.err;
  }
}

}  // namespace
}  // namespace raystack::prep
