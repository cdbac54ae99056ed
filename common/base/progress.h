#pragma once
// Progress of one long task: a bar with rate and ETA when stderr is a terminal, plain periodic
// lines otherwise (logs, CI). Update() is cheap and thread-safe; drawing is rate-limited.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace raystack {

// Clears a progress bar from the terminal's line, if one is shown (log lines call it first).
void ClearProgressLine();

class ProgressReporter {
 public:
  // `total` work units (bytes, triangles, ...) named `unit`; quiet = never print.
  ProgressReporter(std::string title, uint64_t total, std::string unit, bool quiet = false);
  ~ProgressReporter();  // calls Done() if not done

  void Update(uint64_t done_delta);
  void Done();
  // Ends without the final line (the task failed: its error is the last word, not "0 samples
  // in 0.0 s"); a bar on a terminal is cleared.
  void Abandon();
  uint64_t done() const { return done_.load(); }

 private:
  void Draw(bool final);

  std::string title_, unit_;
  std::atomic<uint64_t> done_{0};
  std::atomic<uint64_t> total_;
  bool quiet_, tty_, finished_ = false;
  std::chrono::steady_clock::time_point start_;
  std::atomic<int64_t> next_draw_ns_{0};
  std::mutex draw_mutex_;
};

}  // namespace raystack
