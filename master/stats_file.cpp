#include "master/stats_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

#include "common/base/log.h"

namespace raystack::master {
namespace {

Status CannotWrite(const std::string& path, const std::string& why) {
  return Status::Error(path + ": cannot write the statistics: " + why);
}

}  // namespace

StatsFile::~StatsFile() {
  (void)Finish();
  if (fd_ >= 0) ::close(fd_);
}

Status StatsFile::Write(const std::string& bytes, uint64_t at) {
  for (size_t done = 0; done < bytes.size();) {
    const ssize_t n = target_.stream ? ::write(fd_, bytes.data() + done, bytes.size() - done)
                              : ::pwrite(fd_, bytes.data() + done, bytes.size() - done,
                                         static_cast<off_t>(at + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return CannotWrite(path_, n < 0 ? std::strerror(errno) : "no progress");
    done += static_cast<size_t>(n);
  }
  return OkStatus();
}

Status StatsFile::Open() {
  target_ = ResolveOutputTarget(path_);
  if (target_.stream) {
    std::string why;
    fd_ = OpenStream(target_, &why);
    if (fd_ < 0) return CannotWrite(path_, why);
    return Write("[\n", 0);
  }
  const std::string aside = target_.path + ".tmp";
  fd_ = ::open(aside.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);  // (the umask decides, as for the images)
  if (fd_ < 0) return CannotWrite(path_, std::strerror(errno));
  return OkStatus();
}

void StatsFile::Fail(Status why) {
  error_ = std::move(why);
  LOG_WARNING("master", "%s; the render goes on, the figures of its later frames are not written",
              error_.message().c_str());
}

void StatsFile::Append(const std::string& record) {
  std::lock_guard lock(mu_);
  if (path_.empty() || !error_.ok() || closed_) return;
  const bool first = fd_ < 0;
  if (first) {
    if (Status s = Open(); !s.ok()) return Fail(std::move(s));
  }
  std::string bytes = (empty_ ? "" : ",\n") + record;
  while (!bytes.empty() && bytes.back() == '\n') bytes.pop_back();
  if (target_.stream) {
    if (Status s = Write(bytes + "\n", 0); !s.ok()) return Fail(std::move(s));
    empty_ = false;
    return;
  }
  if (first) {
    // The whole array aside, then renamed over the earlier file: never half of either.
    const std::string aside = target_.path + ".tmp";
    bytes = "[\n" + bytes + "\n]\n";
    Status s = Write(bytes, 0);
    if (s.ok() && std::rename(aside.c_str(), target_.path.c_str()) != 0)
      s = CannotWrite(path_, "rename from " + aside + " failed: " + std::strerror(errno));
    if (!s.ok()) {
      std::remove(aside.c_str());
      return Fail(std::move(s));
    }
    end_ = bytes.size();
    empty_ = false;
    return;
  }
  // Over the closing "]\n": the record, then the array closed again.
  bytes += "\n]\n";
  if (Status s = Write(bytes, end_ - 2); !s.ok()) {
    // The records so far, whole again (a full disk had room for them).
    if (::ftruncate(fd_, static_cast<off_t>(end_ - 2)) != 0 || !Write("]\n", end_ - 2).ok())
      LOG_ERROR("master", "%s: its last record is cut short", path_.c_str());
    return Fail(std::move(s));
  }
  end_ += bytes.size() - 2;
}

Status StatsFile::Finish() {
  std::lock_guard lock(mu_);
  if (target_.stream && !closed_ && fd_ >= 0) {
    closed_ = true;
    const Status s = Write("]\n", 0);
    if (error_.ok() && !s.ok()) error_ = s;
  }
  return error_;
}

}  // namespace raystack::master
