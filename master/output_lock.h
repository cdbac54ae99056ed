#pragma once
// One render writes a frame of an output at a time: two jobs given the same output (the same
// scene run twice, two Slurm jobs) each finished with exit 0 and the last image written won,
// each replacing the other's checkpoints meanwhile. The master holds an exclusive lock on a
// hidden file beside the output (".NAME.lock" for "NAME", common/base/file_lock.h) for the whole
// job, on the bytes of its frames (--frames): another job on any of those frames is refused at
// once, and jobs on other frames of the sequence go on side by side (a sequence split between
// machines was refused). The file is removed at the job's end by the last holder; one left by a
// killed or interrupted job (or on a filesystem without locks) is harmless (a lock dies with its
// process) and taken over by the next run.

#include <cstddef>
#include <string>

#include "common/base/status.h"

namespace raystack::master {

class OutputLock {
 public:
  // Takes the lock of frames [first, end) of `output`: the file frame 0 is written to, however
  // the output was spelled (found by an operator: "t.####.exr" and "t.%04d.exr", "t.exr" and
  // "t-#.exr" with several cameras, each took a lock of its own and wrote the same files).
  // `option`: what gave it, named in the refusal ("--output", "--stats").
  // A filesystem without locks is warned about and the job goes on unlocked.
  static Expected<OutputLock> Take(const std::string& output, size_t first = 0, size_t end = 1,
                                   const std::string& option = "--output");
  OutputLock(OutputLock&& other) noexcept;
  OutputLock& operator=(OutputLock&&) = delete;
  ~OutputLock();  // removes the file while still holding the lock, then releases it

 private:
  OutputLock(std::string path, int fd) : path_(std::move(path)), fd_(fd) {}
  std::string path_;
  int fd_ = -1;
};

}  // namespace raystack::master
