#pragma once
// A private scratch directory that removes itself (and everything in it) when destroyed.

#include <string>

#include "common/base/status.h"

namespace raystack {

class TempDir {
 public:
  // Creates a fresh directory under `parent` (default: $TMPDIR or /tmp).
  static Expected<TempDir> Create(const std::string& parent = "");
  // The same, named PREFIX-HOST-PID-XXXXXX and holding the lock of its file kOwnerFile while
  // it lives, after removing the folders of that shape whose owner lock no process holds
  // (left by a killed process, which could not remove its own). A folder without that file
  // is no one's work folder and is left alone; a live owner's lock is seen from any PID
  // namespace, and on NFS from any machine. `*removed` (optional) counts them.
  static Expected<TempDir> CreateOwned(const std::string& parent, const std::string& prefix,
                                       int* removed = nullptr);
  static constexpr const char* kOwnerFile = ".owner";
  TempDir(TempDir&& other) noexcept : path_(std::move(other.path_)), owner_fd_(other.owner_fd_) {
    other.path_.clear();
    other.owner_fd_ = -1;
  }
  TempDir& operator=(TempDir&&) = delete;
  TempDir(const TempDir&) = delete;
  ~TempDir();

  const std::string& path() const { return path_; }
  std::string File(const std::string& name) const { return path_ + "/" + name; }

 private:
  explicit TempDir(std::string path, int owner_fd = -1)
      : path_(std::move(path)), owner_fd_(owner_fd) {}
  std::string path_;
  int owner_fd_;  // kOwnerFile, locked (CreateOwned), or -1
};

}  // namespace raystack
