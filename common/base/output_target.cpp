#include "common/base/output_target.h"

#include <fcntl.h>
#include <sys/stat.h>

#include <cerrno>
#include <cstring>

#include <filesystem>
#include <system_error>

#include "common/base/follow_links.h"

namespace raystack {

OutputTarget ResolveOutputTarget(const std::string& given) {
  OutputTarget t;
  t.path = given;
  struct stat st;
  if (::stat(given.c_str(), &st) == 0) {
    for (const int fd : {1, 2}) {
      struct stat std_st;
      if (::fstat(fd, &std_st) == 0 && std_st.st_dev == st.st_dev && std_st.st_ino == st.st_ino) {
        t.stream = true;
        t.std_fd = fd;
        return t;
      }
    }
    if (!S_ISREG(st.st_mode)) {  // a pipe, a terminal, /dev/null (opened by the name given)
      t.stream = true;
      return t;
    }
  }
  // A regular file, or none yet: links followed, also to a file not there yet (a job's stats
  // file appears at its first record), so that a lock is the file's whatever names it.
  const std::filesystem::path p = FollowLinks(given);
  std::error_code ec;
  const std::filesystem::path real = std::filesystem::weakly_canonical(p, ec);
  t.path = ec ? p.string() : real.string();
  return t;
}

int OpenStream(const OutputTarget& target, std::string* why) {
  const int fd = target.std_fd >= 0 ? ::fcntl(target.std_fd, F_DUPFD_CLOEXEC, 0)
                                    : ::open(target.path.c_str(), O_WRONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) {
    *why = errno == ENXIO ? "a pipe that no program reads" : std::strerror(errno);
    return -1;
  }
  if (target.std_fd < 0) ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  return fd;
}

}  // namespace raystack
