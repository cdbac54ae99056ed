#include "common/base/file_lock.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

namespace raystack {

LockResult TryLockFile(const std::string& path, bool create, int* fd, std::string* error) {
  *fd = -1;
  const int f = ::open(path.c_str(), O_RDWR | O_CLOEXEC | (create ? O_CREAT : 0), 0644);
  if (f < 0) {
    if (errno == ENOENT && !create) return LockResult::kNoFile;
    *error = path + ": cannot open: " + std::strerror(errno);
    return LockResult::kError;
  }
  struct flock lock {};
  lock.l_type = F_WRLCK;
  lock.l_whence = SEEK_SET;  // the whole file (l_start = l_len = 0)
  if (::fcntl(f, F_OFD_SETLK, &lock) == 0) {
    *fd = f;
    return LockResult::kLocked;
  }
  const int e = errno;
  if (e == EAGAIN || e == EACCES) {
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

}  // namespace raystack
