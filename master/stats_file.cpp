#include "master/stats_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "common/base/log.h"

namespace raystack::master {

StatsFile::~StatsFile() {
  if (fd_ >= 0) ::close(fd_);
}

Status StatsFile::Write(const std::string& bytes, uint64_t at) {
  for (size_t done = 0; done < bytes.size();) {
    const ssize_t n = ::pwrite(fd_, bytes.data() + done, bytes.size() - done,
                               static_cast<off_t>(at + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return Status::Error(path_ + ": cannot write the statistics: " +
                                     (n < 0 ? std::strerror(errno) : "no progress"));
    done += static_cast<size_t>(n);
  }
  return OkStatus();
}

void StatsFile::Append(const std::string& record) {
  if (path_.empty() || !error_.ok()) return;
  if (fd_ < 0) {
    fd_ = ::open(path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd_ < 0) error_ = Status::Error(path_ + ": cannot write the statistics: " + std::strerror(errno));
    else error_ = Write("[\n]\n", 0);
    end_ = 4;
  }
  if (error_.ok()) {
    // Over the closing "]\n": the record, then the array closed again.
    std::string bytes = (empty_ ? "" : ",\n") + record;
    while (!bytes.empty() && bytes.back() == '\n') bytes.pop_back();
    bytes += "\n]\n";
    error_ = Write(bytes, end_ - 2);
    if (error_.ok()) {
      end_ += bytes.size() - 2;
      empty_ = false;
    } else if (::ftruncate(fd_, static_cast<off_t>(end_ - 2)) == 0) {
      (void)Write("]\n", end_ - 2);  // the records so far, whole again (a full disk had room)
    }
  }
  if (!error_.ok())
    LOG_WARNING("master", "%s; the render goes on, the figures of its later frames are not written",
                error_.message().c_str());
}

}  // namespace raystack::master
