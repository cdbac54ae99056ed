#include "tools/prep/write_behind.h"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

namespace raystack::prep {

WriteBehind::WriteBehind(size_t buffer_bytes, size_t max_queued)
    : buffer_bytes_(buffer_bytes), max_queued_(std::max<size_t>(max_queued, 1)),
      thread_([this] { Work(); }) {}

WriteBehind::~WriteBehind() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  queued_.notify_all();
  thread_.join();
}

std::vector<uint8_t> WriteBehind::Take() {
  std::vector<uint8_t> buffer;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!free_.empty()) {
      buffer = std::move(free_.back());
      free_.pop_back();
    }
  }
  buffer.clear();
  buffer.reserve(buffer_bytes_);
  return buffer;
}

Status WriteBehind::Write(int fd, const std::string& path, std::vector<uint8_t> data) {
  std::unique_lock<std::mutex> lock(mutex_);
  written_.wait(lock, [&] { return queue_.size() < max_queued_; });
  if (!error_.ok()) return error_;
  queue_.push_back({fd, &path, std::move(data)});
  queued_.notify_one();
  return OkStatus();
}

Status WriteBehind::Flush() {
  std::unique_lock<std::mutex> lock(mutex_);
  written_.wait(lock, [&] { return queue_.empty() && !writing_; });
  return error_;
}

void WriteBehind::Work() {
  for (;;) {
    Job job;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      queued_.wait(lock, [&] { return stopping_ || !queue_.empty(); });
      if (queue_.empty()) return;
      job = std::move(queue_.front());
      queue_.pop_front();
      writing_ = true;
    }
    const uint8_t* p = job.data.data();
    size_t left = job.data.size();
    int err = 0;
    while (left > 0) {
      const ssize_t n = ::write(job.fd, p, left);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        err = n < 0 ? errno : EIO;
        break;
      }
      p += n;
      left -= static_cast<size_t>(n);
    }
    std::lock_guard<std::mutex> lock(mutex_);
    if (err != 0 && error_.ok())
      error_ = Status::Error(*job.path + ": write failed (disk full?): " + std::strerror(err));
    if (free_.size() < max_queued_) free_.push_back(std::move(job.data));
    writing_ = false;
    written_.notify_all();
  }
}

}  // namespace raystack::prep
