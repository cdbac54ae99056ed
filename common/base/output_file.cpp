#include "common/base/output_file.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string_view>
#include <utility>

#include "common/base/log.h"
#include "common/base/process_names.h"

namespace raystack {
namespace {

namespace fs = std::filesystem;

bool AllDigits(std::string_view s) {
  return !s.empty() && s.find_first_not_of("0123456789") == std::string_view::npos;
}

std::string Folder(const std::string& path) {
  const std::string parent = fs::path(path).parent_path().string();
  return parent.empty() ? "." : parent;
}

Status CheckFolder(const std::string& path) {
  if (path.empty()) return Status::Error("an output path must not be empty");
  const std::string folder = Folder(path);
  std::error_code ec;
  const fs::file_status folder_status = fs::status(folder, ec);
  if (!fs::exists(folder_status))
    return Status::Error(path + ": cannot write: the folder " + folder + " does not exist");
  if (!fs::is_directory(folder_status))
    return Status::Error(path + ": cannot write: " + folder + " is not a folder");
  if (fs::is_directory(fs::status(path, ec)))
    return Status::Error(path + ": cannot write: it is a folder");
  return OkStatus();
}

}  // namespace

Expected<AtomicOutput> AtomicOutput::Create(const std::string& given) {
  const std::string path = FollowLinks(given);
  RAYSTACK_RETURN_IF_ERROR(CheckFolder(path));
  // Hidden, and unique per process and call, so concurrent writers of one path never share
  // a temporary. O_EXCL rather than mkstemp: mkstemp's mode 0600 would stay on the result.
  static std::atomic<uint64_t> counter{0};
  const fs::path target(path);
  for (int attempt = 0; attempt < 100; ++attempt) {
    std::string name = ".";  // (appended piecewise: GCC 12 warns falsely on "." + string)
    name += target.filename().string();
    name += ".tmp-" + HostName() + "-" + std::to_string(getpid()) + "-" + std::to_string(counter++);
    const std::string temp = (target.parent_path() / name).string();
    const int fd = open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd >= 0) {
      close(fd);
      return AtomicOutput(path, temp);
    }
    if (errno != EEXIST)
      return Status::Error(path + ": cannot write: cannot create " + temp + ": " +
                           std::strerror(errno));
  }
  return Status::Error(path + ": cannot write: no free temporary name beside it");
}

int RemoveStaleTemporaries(const std::string& path) {
  const fs::path target(path);
  // Only this machine's: its process ids are the ones it can check. (Appended piecewise: GCC 12
  // warns falsely on "." + string.)
  std::string prefix = ".";
  prefix += target.filename().string();
  prefix += ".tmp-";
  prefix += HostName();
  prefix += "-";
  std::error_code ec;
  int removed = 0;
  for (const fs::directory_entry& entry : fs::directory_iterator(Folder(path), ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind(prefix, 0) != 0) continue;
    // ".NAME.tmp-HOST-PID-N": the writer's process id, then a counter; nothing else.
    const std::string_view rest = std::string_view(name).substr(prefix.size());
    const size_t dash = rest.find('-');
    if (dash == std::string_view::npos || !AllDigits(rest.substr(0, dash)) ||
        !AllDigits(rest.substr(dash + 1)) || dash > 9)
      continue;
    const long pid = std::strtol(std::string(rest.substr(0, dash)).c_str(), nullptr, 10);
    if (!ProcessGone(pid)) continue;  // alive, or not ours to judge
    if (unlink(entry.path().c_str()) == 0) {
      ++removed;
      LOG_INFO("render", "removed %s, left by an interrupted run", entry.path().c_str());
    }
  }
  return removed;
}

AtomicOutput::AtomicOutput(AtomicOutput&& other) noexcept
    : path_(std::move(other.path_)), temp_path_(std::move(other.temp_path_)) {
  other.temp_path_.clear();
}

AtomicOutput::~AtomicOutput() {
  if (!temp_path_.empty()) unlink(temp_path_.c_str());
}

Status AtomicOutput::Commit() {
  if (temp_path_.empty()) return Status::Error(path_ + ": already written");
  // fsync before rename: after a crash the name must not point at an empty file.
  const int fd = open(temp_path_.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0 || fsync(fd) != 0) {
    const std::string reason = std::strerror(errno);
    if (fd >= 0) close(fd);
    return Status::Error(path_ + ": cannot write: " + reason);
  }
  close(fd);
  if (std::rename(temp_path_.c_str(), path_.c_str()) != 0)
    return Status::Error(path_ + ": cannot write: rename from " + temp_path_ +
                         " failed: " + std::strerror(errno));
  temp_path_.clear();
  return OkStatus();
}

Expected<uint64_t> FreeSpace(const std::string& path) {
  struct statvfs vfs;
  if (statvfs(Folder(path).c_str(), &vfs) != 0)
    return Status::Error(path + ": cannot check the free space of its folder: " +
                         std::strerror(errno));
  return static_cast<uint64_t>(vfs.f_bavail) * static_cast<uint64_t>(vfs.f_frsize);
}

Status CheckRoom(const std::string& path, uint64_t bytes) {
  Expected<uint64_t> room = FreeSpace(path);
  if (!room.ok()) return room.status();
  const uint64_t free = *room;
  if (free < bytes)
    return Status::Error(StrFormat("%s: the disk holding it has %.1f MB free, the images need "
                                   "up to %.1f MB: free some space or choose another --output",
                                   path.c_str(), static_cast<double>(free) / 1e6,
                                   static_cast<double>(bytes) / 1e6));
  return OkStatus();
}

Status CheckWritable(const std::string& path) {
  Expected<AtomicOutput> probe = AtomicOutput::Create(path);
  return probe.ok() ? OkStatus() : probe.status();  // the probe removes itself
}

}  // namespace raystack
