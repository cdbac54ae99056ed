#pragma once
// Appends buffers to files on a thread of its own. The partition pass writes gigabytes of
// bucket records; copying them into the page cache is the kernel's work on the calling
// thread, and with this the thread that classifies triangles no longer waits for it.
//
// Thread-safe. Writes to one file happen in the order they were queued. Memory is bounded:
// Write() waits while `max_queued` buffers are waiting to be written.

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "common/base/status.h"

namespace raystack::prep {

class WriteBehind {
 public:
  WriteBehind(size_t buffer_bytes, size_t max_queued);
  ~WriteBehind();  // writes what is queued, then stops
  WriteBehind(const WriteBehind&) = delete;
  WriteBehind& operator=(const WriteBehind&) = delete;

  size_t buffer_bytes() const { return buffer_bytes_; }
  // An empty buffer with room for buffer_bytes(), recycled from finished writes when possible.
  std::vector<uint8_t> Take();
  // Queues `data` to be appended to the open file `fd` (named `path` in errors). Returns the
  // first write error so far: a full disk stops the caller at its next buffer, not after the
  // whole pass (a user's 400 MB temp folder filled in seconds, and the prep went on for minutes).
  Status Write(int fd, const std::string& path, std::vector<uint8_t> data);
  // Waits until every queued write is done; returns the first error since construction.
  Status Flush();

 private:
  struct Job {
    int fd;
    const std::string* path;
    std::vector<uint8_t> data;
  };
  void Work();

  size_t buffer_bytes_, max_queued_;
  std::mutex mutex_;
  std::condition_variable queued_, written_;
  std::deque<Job> queue_;
  std::vector<std::vector<uint8_t>> free_;
  bool writing_ = false, stopping_ = false;
  Status error_;
  std::thread thread_;
};

}  // namespace raystack::prep
