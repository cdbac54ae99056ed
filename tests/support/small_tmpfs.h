#pragma once
// A real, small file system for tests of a full disk: a tmpfs of a given size mounted on a new
// folder (root only, as in CI), unmounted when the object goes. `path` is empty when it could
// not be mounted, and `why` says why (for GTEST_SKIP).

#include <sys/mount.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <string>

namespace raystack::testing {

struct SmallTmpfs {
  // `at`: a folder to create; `size`: tmpfs's option, e.g. "size=256k".
  SmallTmpfs(const std::string& at, const char* size) {
    if (geteuid() != 0) {
      why = "mounting a small tmpfs needs root (CI runs as root)";
    } else if (mkdir(at.c_str(), 0755) != 0) {
      why = at + ": " + std::strerror(errno);
    } else if (mount("tmpfs", at.c_str(), "tmpfs", 0, size) != 0) {
      why = std::string("cannot mount a tmpfs here: ") + std::strerror(errno);
    } else {
      path = at;
    }
  }
  ~SmallTmpfs() {
    if (!path.empty()) umount(path.c_str());
  }
  SmallTmpfs(const SmallTmpfs&) = delete;
  SmallTmpfs& operator=(const SmallTmpfs&) = delete;

  std::string path, why;
};

}  // namespace raystack::testing
