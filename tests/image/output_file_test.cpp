#include "common/base/output_file.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "common/base/temp_dir.h"

namespace raystack::image {
namespace {

namespace fs = std::filesystem;

// The whole file (a sized read: istreambuf_iterator trips GCC 12's -Wnull-dereference).
std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string bytes(static_cast<size_t>(std::filesystem::file_size(path)), '\0');
  in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return bytes;
}

size_t EntryCount(const std::string& folder) {
  return static_cast<size_t>(
      std::distance(fs::directory_iterator(folder), fs::directory_iterator()));
}

TEST(CheckWritable, MissingFolderIsAnErrorNamingThePath) {
  TempDir dir = TempDir::Create().value();
  const std::string path = dir.File("no/such/folder/out.exr");
  Status status = CheckWritable(path);
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find(path), std::string::npos) << status.message();
  EXPECT_NE(status.message().find("does not exist"), std::string::npos) << status.message();
}

TEST(CheckWritable, WritableFolderPassesAndLeavesNothingBehind) {
  TempDir dir = TempDir::Create().value();
  EXPECT_TRUE(CheckWritable(dir.File("out.exr")).ok());
  EXPECT_EQ(EntryCount(dir.path()), 0u);
}

TEST(CheckWritable, FolderOrFileInTheWayIsAnError) {
  TempDir dir = TempDir::Create().value();
  fs::create_directory(dir.File("out.exr"));
  Status status = CheckWritable(dir.File("out.exr"));
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find("it is a folder"), std::string::npos) << status.message();

  std::ofstream(dir.File("file")) << "x";
  status = CheckWritable(dir.File("file/out.exr"));
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find("not a folder"), std::string::npos) << status.message();
  EXPECT_FALSE(CheckWritable("").ok());
}

TEST(CheckWritable, ReadOnlyFolderIsAnError) {
  if (geteuid() == 0) GTEST_SKIP() << "root writes into read-only folders";
  TempDir dir = TempDir::Create().value();
  const std::string folder = dir.File("ro");
  fs::create_directory(folder);
  chmod(folder.c_str(), 0555);
  Status status = CheckWritable(folder + "/out.exr");
  chmod(folder.c_str(), 0755);
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find(folder + "/out.exr"), std::string::npos) << status.message();
}

TEST(AtomicOutput, CommitReplacesTheTargetAndDropRemovesTheTemporary) {
  TempDir dir = TempDir::Create().value();
  const std::string path = dir.File("image.png");
  std::ofstream(path) << "old";
  {
    Expected<AtomicOutput> output = AtomicOutput::Create(path);
    ASSERT_TRUE(output.ok()) << output.status().message();
    std::ofstream(output->temp_path()) << "abandoned";
    EXPECT_EQ(EntryCount(dir.path()), 2u);
  }
  EXPECT_EQ(EntryCount(dir.path()), 1u);  // the temporary went away, the old file stayed
  EXPECT_EQ(ReadBytes(path), "old");

  Expected<AtomicOutput> output = AtomicOutput::Create(path);
  ASSERT_TRUE(output.ok());
  std::ofstream(output->temp_path()) << "new";
  ASSERT_TRUE(output->Commit().ok());
  EXPECT_FALSE(output->Commit().ok());  // once only
  EXPECT_EQ(ReadBytes(path), "new");
  EXPECT_EQ(EntryCount(dir.path()), 1u);
}

// A symbolic link given as the output: the file it names is written, the link stays (it was
// replaced by the file, its target left as it was: a hostile-input review).
TEST(AtomicOutput, ALinkIsFollowedToTheFileItNames) {
  TempDir dir = TempDir::Create().value();
  std::filesystem::create_directories(dir.File("real"));
  std::ofstream(dir.File("real/image.exr")) << "old";
  std::filesystem::create_symlink("real/image.exr", dir.File("link.exr"));
  Expected<AtomicOutput> output = AtomicOutput::Create(dir.File("link.exr"));
  ASSERT_TRUE(output.ok()) << output.status().message();
  std::ofstream(output->temp_path()) << "new";
  ASSERT_TRUE(output->Commit().ok());
  EXPECT_TRUE(std::filesystem::is_symlink(dir.File("link.exr")));
  EXPECT_EQ(ReadBytes(dir.File("real/image.exr")), "new");
  EXPECT_EQ(EntryCount(dir.File("real")), 1u);  // no temporary left beside it
}

// A killed run leaves its temporary (as large as the image); the next run removes those of
// processes no longer running on this machine, and nothing else: not a live process's, not
// another machine's (a shared folder), not a name of another shape.
TEST(AtomicOutput, TemporariesOfProcessesGoneAreRemoved) {
  TempDir dir = TempDir::Create().value();
  const std::string target = dir.File("image.exr");
  std::string own;  // this machine's temporary name, less its process id and counter
  {
    Expected<AtomicOutput> output = AtomicOutput::Create(target);
    ASSERT_TRUE(output.ok());
    const std::string name = fs::path(output->temp_path()).filename().string();
    own = name.substr(0, name.rfind('-', name.rfind('-') - 1) + 1);
  }
  ASSERT_EQ(own.rfind(".image.exr.tmp-", 0), 0u) << own;
  const pid_t child = fork();
  if (child == 0) _exit(0);
  ASSERT_GT(child, 0);
  ASSERT_EQ(waitpid(child, nullptr, 0), child);  // gone now
  const std::string gone = std::to_string(child), alive = std::to_string(getpid());
  const std::vector<std::string> removed = {own + gone + "-0", own + gone + "-7"};
  const std::vector<std::string> kept = {own + alive + "-0", own + "x-0", own + gone + "-",
                                         own + gone + "-1-extra",
                                         ".image.exr.tmp-elsewhere-" + gone + "-0",
                                         ".other.exr.tmp-" + gone + "-0", "image.exr"};
  for (const std::vector<std::string>* names : {&removed, &kept})
    for (const std::string& name : *names) std::ofstream(dir.File(name)) << "bytes";
  EXPECT_EQ(RemoveStaleTemporaries(target), 2);
  for (const std::string& name : removed) EXPECT_FALSE(fs::exists(dir.File(name))) << name;
  for (const std::string& name : kept) EXPECT_TRUE(fs::exists(dir.File(name))) << name;
}

TEST(AtomicOutput, BareFileNameMeansTheCurrentFolder) {
  TempDir dir = TempDir::Create().value();
  const fs::path previous = fs::current_path();
  fs::current_path(dir.path());
  Status status = CheckWritable("out.exr");
  fs::current_path(previous);
  EXPECT_TRUE(status.ok()) << status.message();
}

}  // namespace
}  // namespace raystack::image
