#include "master/output_lock.h"

#include <unistd.h>

#include <filesystem>

#include "common/base/file_lock.h"
#include "common/base/log.h"
#include "common/base/output_file.h"

namespace raystack::master {

Expected<OutputLock> OutputLock::Take(const std::string& output, size_t first, size_t end,
                                      const std::string& option) {
  // The file the name leads to: two jobs writing one file through a link and its target are
  // one output (the day's second review).
  const std::filesystem::path out(FollowLinks(output));
  std::string name = ".";  // (not "." + ...: GCC 12 warns falsely of an overlapping copy)
  name += out.filename().string();
  name += ".lock";
  const std::string path = (out.parent_path() / name).string();
  int fd = -1;
  std::string error;
  switch (TryLockFile(path, /*create=*/true, &fd, &error, LockRange{first, end - first})) {
    case LockResult::kLocked:
      return OutputLock(path, fd);
    case LockResult::kHeldElsewhere:
      return Status::Error(output + ": another raystack render is writing this output now (it "
                           "holds " + path +
                           (end - first > 1 ? StrFormat(" for some of frames %zu to %zu", first, end - 1)
                            : first > 0     ? StrFormat(" for frame %zu", first)
                                            : std::string()) +
                           "); wait for it, or give another " + option +
                           (end - first > 1 || first > 0 ? " or other --frames" : ""));
    case LockResult::kNoLocks:
      LOG_WARNING("render", "%s: its filesystem takes no file locks: nothing keeps another "
                  "render from writing this output at once", output.c_str());
      ::close(fd);
      return OutputLock(std::string(), -1);
    case LockResult::kNoFile:
    case LockResult::kError:
      break;
  }
  return Status::Error(error);
}

OutputLock::OutputLock(OutputLock&& other) noexcept
    : path_(std::move(other.path_)), fd_(other.fd_) {
  other.fd_ = -1;
}

OutputLock::~OutputLock() {
  if (fd_ < 0) return;
  // Removed while held, and only when no other job holds frames of it: a render that opened it
  // meanwhile finds it gone and tries again (TryLockFile checks that the file it locked is
  // still at its path); removed under another job's frames, a third job would have locked a new
  // file and written those frames too.
  if (TryLockWholeFile(fd_) && StillAtPath(fd_, path_)) {  // (not another job's new file)
    std::error_code ec;
    std::filesystem::remove(path_, ec);
  }
  ::close(fd_);
}

}  // namespace raystack::master
