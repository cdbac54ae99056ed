#include "common/base/progress.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>

namespace raystack {
namespace {
int64_t NowNs(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now() -
                                                              start)
      .count();
}
// Set while a bar is on a terminal's line, for log lines to clear it first (a warning printed
// on the bar's line read "...ETA 0 s[raystack WARNING import] ...").
std::atomic<bool> g_bar_shown{false};

std::string Human(double v) {
  char buf[32];
  if (v >= 1e9) std::snprintf(buf, sizeof buf, "%.2fG", v / 1e9);
  else if (v >= 1e6) std::snprintf(buf, sizeof buf, "%.2fM", v / 1e6);
  else if (v >= 1e3) std::snprintf(buf, sizeof buf, "%.1fk", v / 1e3);
  else std::snprintf(buf, sizeof buf, "%.0f", v);
  return buf;
}
// "33.83 MB" for bytes (was "33.83M B"), "1.92M samples" for the rest.
std::string Amount(double v, const std::string& unit) {
  if (unit == "B") {
    const std::string h = Human(v);
    const char last = h.back();
    return last >= '0' && last <= '9' ? h + " B" : h.substr(0, h.size() - 1) + " " + last + "B";
  }
  return Human(v) + " " + unit;
}
// Unknown until something is done ("ETA 0 s" while a render preloaded its blocks for 47 s).
std::string Eta(uint64_t done, double seconds) {
  if (done == 0) return "?";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.0f s", seconds);
  return buf;
}
}  // namespace

void ClearProgressLine() {
  if (g_bar_shown.exchange(false)) std::fputs("\r\033[K", stderr);
}

ProgressReporter::ProgressReporter(std::string title, uint64_t total, std::string unit, bool quiet)
    : title_(std::move(title)), unit_(std::move(unit)), total_(total), quiet_(quiet),
      tty_(isatty(STDERR_FILENO) != 0), start_(std::chrono::steady_clock::now()) {}

ProgressReporter::~ProgressReporter() { Done(); }

void ProgressReporter::Update(uint64_t done_delta) {
  done_.fetch_add(done_delta, std::memory_order_relaxed);
  if (quiet_) return;
  int64_t now = NowNs(start_);
  int64_t next = next_draw_ns_.load(std::memory_order_relaxed);
  if (now < next) return;
  // Terminal: 10 redraws a second. Logs: one line every 5 seconds.
  int64_t period = tty_ ? 100'000'000 : 5'000'000'000;
  if (!next_draw_ns_.compare_exchange_strong(next, now + period)) return;
  if (next == 0) return;  // first call only arms the timer
  Draw(false);
}

void ProgressReporter::Abandon() {
  std::lock_guard<std::mutex> lock(draw_mutex_);
  if (finished_) return;
  finished_ = true;
  if (!quiet_ && tty_) std::fputs("\r\033[K", stderr);
  g_bar_shown = false;
}

void ProgressReporter::Done() {
  std::lock_guard<std::mutex> lock(draw_mutex_);
  if (finished_) return;
  finished_ = true;
  if (quiet_) return;
  double seconds = NowNs(start_) * 1e-9;
  uint64_t done = done_.load();
  std::fprintf(stderr, "%s%s: %s in %.1f s (%s/s)\n", tty_ ? "\r\033[K" : "", title_.c_str(),
               Amount(static_cast<double>(done), unit_).c_str(), seconds,
               Amount(done / std::max(seconds, 1e-9), unit_).c_str());
  g_bar_shown = false;
}

void ProgressReporter::Draw(bool final) {
  std::lock_guard<std::mutex> lock(draw_mutex_);
  if (finished_ && !final) return;
  double seconds = NowNs(start_) * 1e-9;
  uint64_t done = done_.load(), total = std::max<uint64_t>(total_.load(), 1);
  double fraction = std::min(1.0, static_cast<double>(done) / static_cast<double>(total));
  double rate = done / std::max(seconds, 1e-9);
  double eta = fraction > 0 ? seconds * (1 - fraction) / fraction : 0;
  if (tty_) {
    constexpr int kWidth = 30;
    int filled = static_cast<int>(fraction * kWidth);
    std::string bar(static_cast<size_t>(filled), '#');
    bar.resize(kWidth, '.');
    std::fprintf(stderr, "\r\033[K%s [%s] %5.1f%% %s/s ETA %s", title_.c_str(),
                 bar.c_str(), 100 * fraction, Amount(rate, unit_).c_str(), Eta(done, eta).c_str());
    g_bar_shown = true;
  } else {
    std::fprintf(stderr, "%s: %.1f%% (%s of %s, %s/s, ETA %s)\n", title_.c_str(),
                 100 * fraction, Human(done).c_str(), Amount(total, unit_).c_str(),
                 Amount(rate, unit_).c_str(), Eta(done, eta).c_str());
  }
  std::fflush(stderr);
}

}  // namespace raystack
