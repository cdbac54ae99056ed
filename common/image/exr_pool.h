#pragma once
// OpenEXR compresses (and decompresses) a file's chunks as tasks of its one process-wide pool,
// whichever thread writes and whatever thread count a file is given: that count only sets how
// many chunks are in flight, and with a pool of threads they all run there. So a file written
// on the calling thread alone needs the pool empty (tasks then run where they are added), and
// an all-core write needs it full, started from the calling thread, whose priority the new
// threads inherit (Linux threads inherit their creator's nice value).
//
// An ExrPoolLease holds the pool at one size for one file: files that want the same size share
// it (a frame compressed aside at nice 19 and a reference image read as the next frame starts
// both want none, and neither waits for the other); a lease for another size waits until the
// ones holding the pool are done, so no file sees the pool resized under its tasks.

#include <cstdint>

namespace raystack::image {

enum class ExrThreads { kAllCores, kCallingThread };

class ExrPoolLease {
 public:
  explicit ExrPoolLease(ExrThreads threads);
  ~ExrPoolLease();
  ExrPoolLease(const ExrPoolLease&) = delete;
  ExrPoolLease& operator=(const ExrPoolLease&) = delete;

  // The pool's size while this lives: the thread count to give the file.
  int threads() const { return threads_; }
  // Leases waiting for the pool to change size (for tests).
  static int Waiting();

 private:
  int threads_;
};

}  // namespace raystack::image
