#include "common/base/temp_dir.h"

#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <vector>

#include "common/base/file_lock.h"
#include "common/base/process_names.h"

namespace raystack {

namespace {

std::string BaseFolder(const std::string& parent) {
  if (!parent.empty()) return parent;
  const char* env = std::getenv("TMPDIR");
  return env && *env ? env : "/tmp";
}

Expected<std::string> MakeFolder(const std::string& base, const std::string& name) {
  std::string pattern = base + "/" + name + "XXXXXX";
  std::vector<char> buf(pattern.begin(), pattern.end());
  buf.push_back('\0');
  if (!mkdtemp(buf.data()))
    return Status::Error("cannot create a temporary directory in " + base + ": " +
                         std::strerror(errno));
  return std::string(buf.data());
}

}  // namespace

Expected<TempDir> TempDir::Create(const std::string& parent) {
  Expected<std::string> made = MakeFolder(BaseFolder(parent), "raystack-");
  if (!made.ok()) return made.status();
  return TempDir(*made);
}

Expected<TempDir> TempDir::CreateOwned(const std::string& parent, const std::string& prefix,
                                       int* removed) {
  const std::string base = BaseFolder(parent);
  const std::string own = prefix + "-" + HostName() + "-";
  int count = 0;
  std::error_code ec;
  for (const std::filesystem::directory_entry& entry :
       std::filesystem::directory_iterator(base, ec)) {
    // PREFIX-HOST-PID-XXXXXX (a process id, then mkdtemp's six characters), a real folder
    // (not a link), with its owner file, whose lock no live process holds.
    const std::string name = entry.path().filename().string();
    if (name.rfind(own, 0) != 0 || !entry.is_directory(ec) || entry.is_symlink(ec)) continue;
    const std::string rest = name.substr(own.size());
    const size_t dash = rest.find('-');
    if (dash == std::string::npos || dash == 0 || dash > 9 || rest.size() != dash + 7 ||
        rest.find_first_not_of("0123456789") != dash)
      continue;
    int fd = -1;
    std::string error;
    const LockResult r =
        TryLockFile((entry.path() / kOwnerFile).string(), /*create=*/false, &fd, &error);
    if (r == LockResult::kLocked) {  // its owner is gone: ours to remove, holding the lock
      std::filesystem::remove_all(entry.path(), ec);
      if (!ec) ++count;
    }
    if (fd >= 0) ::close(fd);
  }
  if (removed) *removed = count;
  Expected<std::string> made = MakeFolder(base, own + std::to_string(getpid()) + "-");
  if (!made.ok()) return made.status();
  int fd = -1;
  std::string error;
  const LockResult r = TryLockFile(*made + "/" + kOwnerFile, /*create=*/true, &fd, &error);
  if (r != LockResult::kLocked && r != LockResult::kNoLocks) {
    std::filesystem::remove_all(*made, ec);
    return Status::Error(error.empty() ? *made + ": cannot lock its owner file" : error);
  }
  return TempDir(*made, fd);
}

TempDir::~TempDir() {
  if (!path_.empty()) {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  if (owner_fd_ >= 0) ::close(owner_fd_);  // the lock goes after the folder
}

}  // namespace raystack
