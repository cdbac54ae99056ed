// --direct-io: the memory figures auto decides from (MemAvailable, cgroup v1 and v2 limits up
// the hierarchy), its rule, and what each choice does to a store.

#include "slave/direct_reads.h"

#include <gtest/gtest.h>

#include <sys/resource.h>

#include <filesystem>
#include <fstream>

#include "common/base/memory_available.h"
#include "common/base/temp_dir.h"
#include "tests/slave/render_fixture.h"
#include "tests/support/test_dir.h"

namespace raystack::testing {
namespace {

constexpr uint64_t kMB = 1 << 20;

TEST(MemoryAvailable, ReadsMemAvailableFromMeminfo) {
  EXPECT_EQ(MemAvailableIn("MemTotal:       24000000 kB\nMemFree:  100 kB\n"
                           "MemAvailable:   23000000 kB\nBuffers: 5 kB\n"),
            uint64_t{23000000} * 1024);
  EXPECT_FALSE(MemAvailableIn("MemTotal: 100 kB\n"));
  EXPECT_FALSE(MemAvailableIn("MemAvailable: lots\n"));
  // This machine's own figure exists and is sane.
  const std::optional<uint64_t> here = MemoryAvailable();
  ASSERT_TRUE(here);
  EXPECT_GT(*here, 0u);
}

TEST(MemoryAvailable, CountsAnAddressSpaceLimit) {
  EXPECT_EQ(VmSizeIn("Name: raystack\nVmPeak:  9000 kB\nVmSize:    8000 kB\nVmRSS: 10 kB\n"),
            uint64_t{8000} * 1024);
  EXPECT_FALSE(VmSizeIn("Name: raystack\nVmRSS: 10 kB\n"));
  EXPECT_FALSE(VmSizeIn("VmSize: lots\n"));
  EXPECT_EQ(AddressSpaceRoom(2000, 500), 1500u);
  EXPECT_EQ(AddressSpaceRoom(2000, 2500), 0u);  // already over it
  // This process's own figure exists.
  EXPECT_TRUE(MemoryThisProcessMayTake());
}

TEST(MemoryAvailable, FindsTheMemoryHierarchiesInProcCgroup) {
  const MemoryCgroups both = MemoryCgroupsIn(
      "12:cpu,cpuacct:/x\n4:memory:/process_api/abc\n1:name=systemd:/\n0::/user/job\n");
  EXPECT_EQ(both.v1, "/process_api/abc");
  EXPECT_EQ(both.v2, "/user/job");
  const MemoryCgroups v1_only = MemoryCgroupsIn("3:pids,memory:/a\n");
  EXPECT_EQ(v1_only.v1, "/a");
  EXPECT_FALSE(v1_only.v2);
  const MemoryCgroups none = MemoryCgroupsIn("garbage\n5:cpu:/b\n");
  EXPECT_FALSE(none.v1);
  EXPECT_FALSE(none.v2);
}

class CgroupTree : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = raystack::testing::MakeTestDir();
    ASSERT_TRUE(dir_);
  }
  // Writes `file` with `text` in group `group` ("/" or "/a/b") of the fake hierarchy.
  void Set(const std::string& group, const std::string& file, const std::string& text) {
    const std::string d = root() + (group == "/" ? "" : group);
    std::filesystem::create_directories(d);
    std::ofstream(d + "/" + file) << text << "\n";
  }
  std::string root() const { return dir_->path() + "/cg"; }
  std::unique_ptr<TempDir> dir_;
};

TEST_F(CgroupTree, V1RoomIsTheTightestLimitUpTheHierarchy) {
  Set("/", "memory.limit_in_bytes", "9223372036854771712");  // v1's "no limit"
  Set("/", "memory.usage_in_bytes", std::to_string(5000 * kMB));
  Set("/jobs", "memory.limit_in_bytes", std::to_string(1000 * kMB));
  Set("/jobs", "memory.usage_in_bytes", std::to_string(900 * kMB));
  Set("/jobs/render", "memory.limit_in_bytes", std::to_string(512 * kMB));
  Set("/jobs/render", "memory.usage_in_bytes", std::to_string(12 * kMB));
  const char* limit = "memory.limit_in_bytes";
  const char* usage = "memory.usage_in_bytes";
  // The parent has 100 MB left, less than the group's own 500.
  EXPECT_EQ(CgroupRoom(root(), "/jobs/render", limit, usage), 100 * kMB);
  Set("/jobs", "memory.usage_in_bytes", std::to_string(100 * kMB));
  EXPECT_EQ(CgroupRoom(root(), "/jobs/render", limit, usage), 500 * kMB);
  // At or over its limit: no room.
  Set("/jobs/render", "memory.usage_in_bytes", std::to_string(600 * kMB));
  EXPECT_EQ(CgroupRoom(root(), "/jobs/render", limit, usage), 0u);
  // No limit anywhere (only the root's "none"): no figure.
  EXPECT_FALSE(CgroupRoom(root(), "/", limit, usage));
  EXPECT_FALSE(CgroupRoom(root(), "/missing", limit, usage));
}

TEST_F(CgroupTree, V2MaxMeansNoLimit) {
  Set("/", "memory.max", "max");
  Set("/", "memory.current", "123");
  Set("/a", "memory.max", "max");
  Set("/a", "memory.current", "456");
  EXPECT_FALSE(CgroupRoom(root(), "/a", "memory.max", "memory.current"));
  Set("/a", "memory.max", std::to_string(64 * kMB));
  Set("/a", "memory.current", std::to_string(4 * kMB));
  EXPECT_EQ(CgroupRoom(root(), "/a", "memory.max", "memory.current"), 60 * kMB);
}

TEST(DirectReads, AutoReadsDirectWhenThePageCacheCannotKeepTheStore) {
  // 600 MB of blocks, a 72 MB cache: 700 MB available leaves 628 for the page cache.
  EXPECT_FALSE(slave::AutoDirect(600 * kMB, 72 * kMB, 700 * kMB));
  EXPECT_TRUE(slave::AutoDirect(600 * kMB, 72 * kMB, 500 * kMB));
  EXPECT_TRUE(slave::AutoDirect(600 * kMB, 72 * kMB, 650 * kMB));
  EXPECT_TRUE(slave::AutoDirect(1 * kMB, 72 * kMB, 50 * kMB));  // not even the cache fits
  EXPECT_FALSE(slave::AutoDirect(600 * kMB, 72 * kMB, std::nullopt));  // unknown: buffered
}

TEST(DirectReads, OnAndOffAreObeyed) {
  TestStore s = BuildGenerated("sphere:2000");
  Expected<std::unique_ptr<store::StoreReader>> store = store::StoreReader::Open(s.reader->dir());
  ASSERT_TRUE(store.ok());
  std::string why;
  ASSERT_TRUE(slave::ChooseReads(slave::DirectIo::kOff, 64 * kMB, store->get(), &why).ok());
  EXPECT_FALSE((*store)->direct_reads());
  EXPECT_NE(why.find("buffered"), std::string::npos) << why;
  ASSERT_TRUE(slave::ChooseReads(slave::DirectIo::kOn, 64 * kMB, store->get(), &why).ok());
  EXPECT_TRUE((*store)->direct_reads());
  EXPECT_NE(why.find("direct"), std::string::npos) << why;
  // auto on this machine: a tiny store fits memory, so buffered.
  Expected<std::unique_ptr<store::StoreReader>> fresh = store::StoreReader::Open(s.reader->dir());
  ASSERT_TRUE(fresh.ok());
  ASSERT_TRUE(slave::ChooseReads(slave::DirectIo::kAuto, 64 * kMB, fresh->get(), &why).ok());
  EXPECT_FALSE((*fresh)->direct_reads()) << why;
  EXPECT_NE(why.find("MiB of memory available"), std::string::npos) << why;
}

TEST(DirectReads, ParsesItsOption) {
  for (const auto& [name, mode] : {std::pair{"auto", slave::DirectIo::kAuto},
                                   std::pair{"on", slave::DirectIo::kOn},
                                   std::pair{"off", slave::DirectIo::kOff}}) {
    Expected<slave::DirectIo> parsed = slave::ParseDirectIo(name);
    ASSERT_TRUE(parsed.ok());
    EXPECT_EQ(*parsed, mode);
  }
  const Expected<slave::DirectIo> bad = slave::ParseDirectIo("yes");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("--direct-io"), std::string::npos);
}

}  // namespace
}  // namespace raystack::testing
