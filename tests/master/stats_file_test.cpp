// --stats as frames end: after every record the file is a whole JSON array of the records so
// far (a run that dies keeps its finished frames' figures); nothing is written before the first
// record; a write that fails (a full disk) is an error naming the file, the records before it
// stay whole, and later records are not attempted.

#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include "common/base/log.h"
#include "master/stats_file.h"
#include "tests/prep/run_process.h"
#include "tests/support/small_tmpfs.h"
#include "tests/support/test_dir.h"

namespace raystack::testing {
namespace {

using prep::testing::Slurp;

TEST(StatsFile, IsAWholeJsonArrayAfterEveryRecord) {
  const std::unique_ptr<TempDir> dir = MakeTestDir();
  ASSERT_TRUE(dir);
  const std::string path = dir->File("stats.json");
  std::ofstream(path) << "an earlier run's figures";
  master::StatsFile stats(path);
  EXPECT_EQ(Slurp(path), "an earlier run's figures");  // untouched until a frame ends
  for (int f = 0; f < 4; ++f) {
    // Records as the renderers make them: with and without a newline at the end.
    stats.Append(StrFormat("{\n  \"frame\": %d,\n  \"name\": \"]\\n\"\n}%s", f, f % 2 ? "\n" : ""));
    nlohmann::json array;
    ASSERT_NO_THROW(array = nlohmann::json::parse(Slurp(path))) << Slurp(path);
    ASSERT_TRUE(array.is_array());
    ASSERT_EQ(array.size(), static_cast<size_t>(f + 1));
    for (int g = 0; g <= f; ++g) {
      EXPECT_EQ(array[static_cast<size_t>(g)]["frame"], g);
      EXPECT_EQ(array[static_cast<size_t>(g)]["name"], "]\n");
    }
  }
  EXPECT_TRUE(stats.Finish().ok());
}

TEST(StatsFile, NoPathWritesNothingAndAFailedWriteNamesTheFile) {
  master::StatsFile none("");
  none.Append("{}");
  EXPECT_TRUE(none.Finish().ok());

  const std::unique_ptr<TempDir> dir = MakeTestDir();
  ASSERT_TRUE(dir);
  master::StatsFile missing(dir->File("no/such/folder/stats.json"));
  missing.Append("{}");
  ASSERT_FALSE(missing.Finish().ok());
  EXPECT_NE(missing.Finish().message().find("no/such/folder/stats.json: cannot write the statistics"),
            std::string::npos) << missing.Finish().message();

  // A full disk: the record that does not fit is an error, and the file keeps the records
  // before it, whole (its partial write is taken back).
  SmallTmpfs small(dir->File("small"), "size=64k");
  if (small.path.empty()) GTEST_SKIP() << small.why;
  const std::string path = small.path + "/stats.json";
  master::StatsFile full(path);
  full.Append("{ \"frame\": 0 }");
  ASSERT_TRUE(full.Finish().ok()) << full.Finish().message();
  full.Append("{ \"big\": \"" + std::string(256 << 10, 'x') + "\" }");
  ASSERT_FALSE(full.Finish().ok());
  EXPECT_NE(full.Finish().message().find(path + ": cannot write the statistics: No space left"),
            std::string::npos) << full.Finish().message();
  full.Append("{ \"frame\": 2 }");  // not attempted
  nlohmann::json array;
  ASSERT_NO_THROW(array = nlohmann::json::parse(Slurp(path))) << Slurp(path).substr(0, 200);
  ASSERT_EQ(array.size(), 1u);
  EXPECT_EQ(array[0]["frame"], 0);
}

// Found by a review: pwrite on a pipe fails (`--stats /dev/stdout | cat` ended the job with
// "Illegal seek" after every frame had rendered). A pipe gets the records in order and the
// closing bracket at the end.
TEST(StatsFile, APipeGetsTheArrayInOrder) {
  int fds[2];
  ASSERT_EQ(pipe(fds), 0);
  std::string got;
  std::thread reader([&] {
    char buffer[256];
    for (ssize_t n; (n = read(fds[0], buffer, sizeof buffer)) > 0;) got.append(buffer, static_cast<size_t>(n));
  });
  {
    master::StatsFile stats(StrFormat("/proc/self/fd/%d", fds[1]));
    stats.Append("{ \"frame\": 0 }\n");
    stats.Append("{ \"frame\": 1 }");
    EXPECT_TRUE(stats.Finish().ok()) << stats.Finish().message();
  }
  close(fds[1]);
  reader.join();
  close(fds[0]);
  nlohmann::json array;
  ASSERT_NO_THROW(array = nlohmann::json::parse(got)) << got;
  ASSERT_EQ(array.size(), 2u);
  EXPECT_EQ(array[1]["frame"], 1);
}

// A first record that cannot be written (a full disk) leaves the earlier run's file as it was:
// the array is written aside, then renamed over it.
TEST(StatsFile, AFirstRecordThatCannotBeWrittenLeavesTheEarlierFile) {
  const std::unique_ptr<TempDir> dir = MakeTestDir();
  ASSERT_TRUE(dir);
  SmallTmpfs small(dir->File("small"), "size=64k");
  if (small.path.empty()) GTEST_SKIP() << small.why;
  const std::string path = small.path + "/stats.json";
  std::ofstream(path) << "[ \"an earlier run\" ]\n";
  master::StatsFile stats(path);
  stats.Append("{ \"big\": \"" + std::string(256 << 10, 'x') + "\" }");
  EXPECT_FALSE(stats.Finish().ok());
  EXPECT_EQ(Slurp(path), "[ \"an earlier run\" ]\n");
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));
}

}  // namespace
}  // namespace raystack::testing
