#pragma once
// Sequential reading of one file through one fixed-size buffer. The same stream serves text
// lines (numbered, for "file:line" messages) and raw bytes (with offsets, for "file: byte N"
// messages), so a PLY header can be read as text and its body as binary. Memory use is the
// buffer, whatever the file size. Not thread-safe; one reader owns it.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "common/base/status.h"

namespace raystack {
class ProgressReporter;
}

namespace raystack::import {

class BufferedInput {
 public:
  // Big reads amortise the system call; 4 MiB is also the longest line accepted.
  static constexpr size_t kDefaultBufferBytes = size_t{4} << 20;

  // Opens `path`; `progress` (optional) is fed the number of bytes read from disk.
  static Expected<BufferedInput> Open(const std::string& path, ProgressReporter* progress,
                                      size_t buffer_bytes = kDefaultBufferBytes);
  BufferedInput(BufferedInput&& other) noexcept;
  BufferedInput& operator=(BufferedInput&&) = delete;
  BufferedInput(const BufferedInput&) = delete;
  ~BufferedInput();

  // Sets *line to the next line without "\n" or "\r\n"; the view lives until the next call.
  // Returns false at end of file or on failure; status() tells which.
  bool NextLine(std::string_view* line);
  // Copies the next `n` bytes; an error naming the byte offset when the file ends first.
  Status ReadBytes(void* out, size_t n);
  // The next bytes (up to `n`, fewer near the end) without consuming them: format sniffing.
  std::string_view Peek(size_t n);

  // OK, or the read error (or over-long line) that ended NextLine().
  const Status& status() const { return status_; }
  const std::string& path() const { return path_; }
  uint64_t line_number() const { return line_number_; }  // of the last line returned
  uint64_t offset() const { return consumed_before_ + begin_; }  // bytes consumed so far
  uint64_t file_size() const { return file_size_; }

  // Errors in the house format: "path:line: message" and "path: byte N: message".
  Status LineError(std::string_view message) const;
  Status ByteError(uint64_t byte_offset, std::string_view message) const;

 private:
  BufferedInput(std::string path, int fd, uint64_t file_size, size_t buffer_bytes,
                ProgressReporter* progress);
  // Moves the unconsumed bytes to the front and reads more behind them; false when the file
  // has no more bytes (or on a read error, stored in status_).
  bool Refill();

  std::string path_;
  int fd_ = -1;
  uint64_t file_size_ = 0;
  ProgressReporter* progress_ = nullptr;
  std::unique_ptr<char[]> buffer_;
  size_t capacity_ = 0;
  size_t begin_ = 0;  // first unconsumed byte in buffer_
  size_t end_ = 0;    // one past the last valid byte in buffer_
  uint64_t consumed_before_ = 0;  // file offset of buffer_[0]
  uint64_t line_number_ = 0;
  bool eof_ = false;
  Status status_;
};

}  // namespace raystack::import
