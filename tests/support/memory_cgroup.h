#pragma once
// Real memory caps for tests: a child cgroup-v1 memory group of this process's own, with a hard
// limit (anonymous memory and page cache both count), that a child process joins between fork
// and exec. Tests skip, saying why, where no such group can be made (no v1 memory controller,
// or not allowed to create one); CI runs as root, where they run.

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "common/base/memory_available.h"

namespace raystack::testing {

// This process's memory cgroup (v1) directory, or "" with `why` saying why there is none.
inline std::string OwnMemoryGroup(std::string* why) {
  const std::optional<std::string> path = OwnMemoryCgroups().v1;
  if (!path) {
    *why = "/proc/self/cgroup has no cgroup-v1 'memory' controller line (cgroup v2 only?)";
    return "";
  }
  const std::string group = kCgroupV1Memory + *path;
  if (!std::filesystem::exists(group + "/memory.limit_in_bytes")) {
    *why = group + "/memory.limit_in_bytes does not exist (cgroup v1 memory not mounted at " +
           kCgroupV1Memory + ")";
    return "";
  }
  return group;
}

inline bool WriteValue(const std::string& path, const std::string& value) {
  std::ofstream out(path);
  out << value;
  out.flush();
  return out.good();
}

inline uint64_t ReadValue(const std::string& path) {
  std::ifstream in(path);
  uint64_t v = 0;
  in >> v;
  return v;
}

// The `key N` entry of a flat-keyed cgroup file such as memory.oom_control; -1 if absent.
inline int64_t ReadKey(const std::string& path, const std::string& key) {
  std::ifstream in(path);
  std::string k;
  int64_t v = 0;
  while (in >> k >> v)
    if (k == key) return v;
  return -1;
}

// A child memory cgroup with a hard limit, removed on destruction (after its tasks exited).
class MemoryCgroup {
 public:
  MemoryCgroup(const std::string& parent, const std::string& name) : path_(parent + "/" + name) {}
  ~MemoryCgroup() {
    if (!created_) return;
    WriteValue(path_ + "/memory.force_empty", "0");  // drop the page cache still charged
    if (rmdir(path_.c_str()) != 0)
      ADD_FAILURE() << "cannot remove " << path_ << ": " << std::strerror(errno);
  }
  MemoryCgroup(const MemoryCgroup&) = delete;
  MemoryCgroup& operator=(const MemoryCgroup&) = delete;

  // A new child of this process's own group, named `prefix` and this process's id; null with
  // `why` set when none can be made (no v1 memory controller, or not allowed: tests skip).
  static std::unique_ptr<MemoryCgroup> CreateOwnChild(const std::string& prefix,
                                                      std::string* why) {
    const std::string own = OwnMemoryGroup(why);
    if (own.empty()) return nullptr;
    auto group = std::make_unique<MemoryCgroup>(own, prefix + "-" + std::to_string(getpid()));
    if (!group->Create(why)) return nullptr;
    return group;
  }

  // Creates the group; false with `error` set (errno's text) when not allowed.
  bool Create(std::string* error) {
    if (mkdir(path_.c_str(), 0755) != 0) {
      *error = "cannot create " + path_ + ": " + std::strerror(errno);
      return false;
    }
    created_ = true;
    return true;
  }
  bool Limit(uint64_t bytes) {
    if (!WriteValue(path_ + "/memory.limit_in_bytes", std::to_string(bytes))) return false;
    // With swap accounting, cap memory + swap too so nothing escapes to swap.
    const std::string memsw = path_ + "/memory.memsw.limit_in_bytes";
    if (std::filesystem::exists(memsw) && !WriteValue(memsw, std::to_string(bytes))) return false;
    return ReadValue(path_ + "/memory.limit_in_bytes") <= bytes;
  }
  std::string File(const std::string& name) const { return path_ + "/" + name; }
  const std::string& path() const { return path_; }

  // For RunProcess: run in the child after fork, it moves the child into this group before
  // exec (async-signal-safe calls only), or exits with 125.
  std::function<void()> Joiner() const {
    return [procs = File("cgroup.procs")] {
      const int fd = open(procs.c_str(), O_WRONLY);
      char pid[32];
      const int n = snprintf(pid, sizeof pid, "%d", static_cast<int>(getpid()));
      if (fd < 0 || write(fd, pid, static_cast<size_t>(n)) != n) _exit(125);
      close(fd);
    };
  }

 private:
  std::string path_;
  bool created_ = false;
};

}  // namespace raystack::testing
