#pragma once
// An exclusive lock on a file, taken without waiting and held while its descriptor is open:
// an open file description lock (fcntl F_OFD_SETLK). Unlike flock() on a folder, it is carried
// to the server on NFS, and a process in another PID namespace sees it too, so "locked" means
// "some live process holds it", wherever that process runs.

#include <cstdint>
#include <string>

namespace raystack {

enum class LockResult {
  kLocked,         // ours now: *fd holds it
  kHeldElsewhere,  // a live process holds it
  kNoLocks,        // the filesystem takes no locks (ENOLCK, EOPNOTSUPP): *fd open, unlocked
  kNoFile,         // missing, and not to be created
  kError,          // cannot open: *error says why
};

// The bytes of the file a lock covers: several holders may lock disjoint ranges of one file
// (the frames of one image sequence, rendered by several jobs). Length 0: to the end, so the
// default is the whole file.
struct LockRange {
  uint64_t start = 0, length = 0;
};

// Opens `path` (read-write, created if `create`) and tries its lock of `range`. *fd is the open
// descriptor for kLocked and kNoLocks (the caller closes it to release), -1 otherwise.
// `mode`: a created file's (the umask applies).
LockResult TryLockFile(const std::string& path, bool create, int* fd, std::string* error,
                       LockRange range = {}, int mode = 0644);
// Whether the open file `fd` is still the file at `path` (not removed, nor replaced).
bool StillAtPath(int fd, const std::string& path);
// Widens the lock `fd` holds to the whole file if no one else holds any of it: true then (the
// file may be removed: no other holder has it open locked).
bool TryLockWholeFile(int fd);

}  // namespace raystack
