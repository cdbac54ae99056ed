#pragma once
// A private scratch directory that removes itself (and everything in it) when destroyed.

#include <string>

#include "common/base/status.h"

namespace raystack {

class TempDir {
 public:
  // Creates a fresh directory under `parent` (default: $TMPDIR or /tmp).
  static Expected<TempDir> Create(const std::string& parent = "");
  // The same, named PREFIX-HOST-PID-XXXXXX, after removing the folders of that shape a
  // process of this machine that is gone left there (killed: it could not remove its own).
  // `*removed` (optional) counts them.
  static Expected<TempDir> CreateOwned(const std::string& parent, const std::string& prefix,
                                       int* removed = nullptr);
  TempDir(TempDir&& other) noexcept : path_(std::move(other.path_)) { other.path_.clear(); }
  TempDir& operator=(TempDir&&) = delete;
  TempDir(const TempDir&) = delete;
  ~TempDir();

  const std::string& path() const { return path_; }
  std::string File(const std::string& name) const { return path_ + "/" + name; }

 private:
  explicit TempDir(std::string path) : path_(std::move(path)) {}
  std::string path_;
};

}  // namespace raystack
