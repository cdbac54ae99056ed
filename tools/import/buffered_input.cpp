#include "tools/import/buffered_input.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "common/base/log.h"
#include "common/base/progress.h"

namespace raystack::import {

Expected<BufferedInput> BufferedInput::Open(const std::string& path, ProgressReporter* progress,
                                            size_t buffer_bytes) {
  // O_NONBLOCK: a pipe (an `mtllib` naming a FIFO, found by a hostile-input review) would hold
  // open() until something writes it; opened at once, it is refused below as not a file.
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) return Status::Error("cannot open " + path + ": " + std::strerror(errno));
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    return Status::Error(path + ": not a regular file");
  }
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  // Tells the kernel to read ahead aggressively; the whole file is read once, in order.
  ::posix_fadvise(fd, 0, 0, POSIX_FADV_SEQUENTIAL);
  return BufferedInput(path, fd, static_cast<uint64_t>(st.st_size), buffer_bytes, progress);
}

BufferedInput::BufferedInput(std::string path, int fd, uint64_t file_size, size_t buffer_bytes,
                             ProgressReporter* progress)
    : path_(std::move(path)), fd_(fd), file_size_(file_size), progress_(progress),
      buffer_(new char[buffer_bytes]), capacity_(buffer_bytes) {}

BufferedInput::BufferedInput(BufferedInput&& other) noexcept
    : path_(std::move(other.path_)), fd_(other.fd_), file_size_(other.file_size_),
      progress_(other.progress_), buffer_(std::move(other.buffer_)), capacity_(other.capacity_),
      begin_(other.begin_), end_(other.end_), consumed_before_(other.consumed_before_),
      line_number_(other.line_number_), eof_(other.eof_), status_(std::move(other.status_)) {
  other.fd_ = -1;
}

BufferedInput::~BufferedInput() {
  if (fd_ >= 0) ::close(fd_);
}

bool BufferedInput::Refill() {
  if (eof_ || !status_.ok()) return false;
  if (begin_ > 0) {
    std::memmove(buffer_.get(), buffer_.get() + begin_, end_ - begin_);
    consumed_before_ += begin_;
    end_ -= begin_;
    begin_ = 0;
  }
  if (end_ == capacity_) return false;  // full: the caller decides what that means
  ssize_t n;
  do {
    n = ::read(fd_, buffer_.get() + end_, capacity_ - end_);
  } while (n < 0 && errno == EINTR);
  if (n < 0) {
    status_ = ByteError(consumed_before_ + end_, std::string("read failed: ") +
                                                      std::strerror(errno));
    return false;
  }
  if (n == 0) {
    eof_ = true;
    return false;
  }
  end_ += static_cast<size_t>(n);
  if (progress_) progress_->Update(static_cast<uint64_t>(n));
  return true;
}

bool BufferedInput::NextLine(std::string_view* line) {
  size_t scanned = begin_;  // bytes before this were searched for '\n' already
  for (;;) {
    const char* start = buffer_.get() + scanned;
    const void* newline = std::memchr(start, '\n', end_ - scanned);
    if (newline) {
      size_t stop = static_cast<size_t>(static_cast<const char*>(newline) - buffer_.get());
      size_t length = stop - begin_;
      if (length > 0 && buffer_[stop - 1] == '\r') --length;
      *line = std::string_view(buffer_.get() + begin_, length);
      begin_ = stop + 1;
      ++line_number_;
      return true;
    }
    size_t pending = end_ - begin_;
    if (!Refill()) {
      if (!status_.ok()) return false;
      if (end_ - begin_ == capacity_) {
        ++line_number_;
        status_ = LineError(StrFormat("line longer than %zu bytes", capacity_));
        return false;
      }
      if (begin_ == end_) return false;  // end of file
      // The last line has no newline.
      size_t length = end_ - begin_;
      if (buffer_[end_ - 1] == '\r') --length;
      *line = std::string_view(buffer_.get() + begin_, length);
      begin_ = end_;
      ++line_number_;
      return true;
    }
    scanned = begin_ + pending;
  }
}

Status BufferedInput::ReadBytes(void* out, size_t n) {
  char* dst = static_cast<char*>(out);
  const uint64_t start = offset();
  const size_t wanted = n;
  while (n > 0) {
    if (begin_ == end_ && !Refill()) {
      if (!status_.ok()) return status_;
      return ByteError(start, StrFormat("unexpected end of file (%zu bytes needed, %zu left)",
                                        wanted, wanted - n));
    }
    size_t take = std::min(n, end_ - begin_);
    std::memcpy(dst, buffer_.get() + begin_, take);
    begin_ += take;
    dst += take;
    n -= take;
  }
  return OkStatus();
}

std::string_view BufferedInput::Peek(size_t n) {
  n = std::min(n, capacity_);
  while (end_ - begin_ < n && Refill()) {
  }
  return std::string_view(buffer_.get() + begin_, std::min(n, end_ - begin_));
}

Status BufferedInput::LineError(std::string_view message) const {
  return Status::Error(StrFormat("%s:%llu: %.*s", path_.c_str(),
                                 static_cast<unsigned long long>(line_number_),
                                 static_cast<int>(message.size()), message.data()));
}

Status BufferedInput::ByteError(uint64_t byte_offset, std::string_view message) const {
  return Status::Error(StrFormat("%s: byte %llu: %.*s", path_.c_str(),
                                 static_cast<unsigned long long>(byte_offset),
                                 static_cast<int>(message.size()), message.data()));
}

}  // namespace raystack::import
