#include "common/base/file_lock.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <string>

namespace raystack {

// Whether `f` is still the file at `path`: a holder may unlink a lock file it created (a failed
// prep removes its store's), and a process that opened it just before then would lock a file
// no one else can find, while the next one creates and locks a new one.
bool StillAtPath(int f, const std::string& path) {
  struct stat open_file {}, at_path {};
  return ::fstat(f, &open_file) == 0 && ::stat(path.c_str(), &at_path) == 0 &&
         open_file.st_dev == at_path.st_dev && open_file.st_ino == at_path.st_ino;
}

namespace {

// One try: open (or create) and lock without waiting. *again: held, but by a holder that is
// removing the file (it widened its lock to the whole file first, master/output_lock.cpp) or
// has removed it: the next try meets a new file.
LockResult TryLockFileOnce(const std::string& path, bool create, int* fd, std::string* error,
                           LockRange range, int mode, bool* again) {
  *fd = -1;
  *again = false;
  if (range.start > static_cast<uint64_t>(INT64_MAX) ||
      range.length > static_cast<uint64_t>(INT64_MAX) - range.start) {
    *error = path + ": cannot lock: the range is too large";
    return LockResult::kError;
  }
  const int f = ::open(path.c_str(), O_RDWR | O_CLOEXEC | (create ? O_CREAT : 0), mode);
  if (f < 0) {
    if (errno == ENOENT && !create) return LockResult::kNoFile;
    *error = path + ": cannot open: " + std::strerror(errno);
    return LockResult::kError;
  }
  struct flock lock {};
  lock.l_type = F_WRLCK;
  lock.l_whence = SEEK_SET;  // l_len 0: to the end
  lock.l_start = static_cast<off_t>(range.start);
  lock.l_len = static_cast<off_t>(range.length);
  if (::fcntl(f, F_OFD_SETLK, &lock) == 0) {
    *fd = f;
    return LockResult::kLocked;
  }
  const int e = errno;
  if (e == EAGAIN || e == EACCES) {
    struct flock holder = lock;
    *again = !StillAtPath(f, path) || (::fcntl(f, F_OFD_GETLK, &holder) == 0 &&
                                       holder.l_type != F_UNLCK && holder.l_start == 0 &&
                                       holder.l_len == 0 && range.length != 0);
    ::close(f);
    return LockResult::kHeldElsewhere;
  }
  if (e == ENOLCK || e == EOPNOTSUPP || e == EINVAL || e == ENOSYS) {
    *fd = f;
    return LockResult::kNoLocks;
  }
  ::close(f);
  *error = path + ": cannot lock: " + std::strerror(e);
  return LockResult::kError;
}

}  // namespace

bool TryLockWholeFile(int fd) {
  struct flock lock {};
  lock.l_type = F_WRLCK;
  lock.l_whence = SEEK_SET;
  return ::fcntl(fd, F_OFD_SETLK, &lock) == 0;
}

LockResult TryLockFile(const std::string& path, bool create, int* fd, std::string* error,
                       LockRange range, int mode) {
  // A lock won on an unlinked file is worthless; the holder that unlinked it is gone by then,
  // so the next try meets the new file (or none). A few tries cover any such race.
  constexpr int kTries = 8;
  LockResult result = LockResult::kError;
  for (int i = 0; i < kTries; ++i) {
    bool again = false;
    result = TryLockFileOnce(path, create, fd, error, range, mode, &again);
    if (result == LockResult::kHeldElsewhere && again && i + 1 < kTries) {
      // A whole-file lock over a range asked for: most likely a job ending, removing the file
      // (an older build's job, or a store's writer, holds it longer: then it stays held).
      ::usleep(1000u << i);
      continue;
    }
    if (result != LockResult::kLocked || StillAtPath(*fd, path)) return result;
    ::close(*fd);
    *fd = -1;
  }
  *error = path + ": cannot lock: it was removed and created again " + std::to_string(kTries) +
           " times while locking";
  return LockResult::kError;
}

}  // namespace raystack
