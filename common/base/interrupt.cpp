#include "common/base/interrupt.h"

#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstdint>
#include <ctime>

namespace raystack {
namespace {

// Read by other threads: atomics, lock-free so that the handler may touch them.
std::atomic<int> g_signal{0};
std::atomic<bool> g_hold{false};
std::atomic<bool> g_announce{false};
// The announcement starts a line of its own after a progress bar (a terminal's, redrawn in
// place); in a log, where progress comes in whole lines, it had a blank line before it.
std::atomic<bool> g_after_bar{false};
// When the noted signal came (CLOCK_MONOTONIC, ns). The same signal again within
// kRepeatWindowNs is the same sending, not a user's second Ctrl-C: GNU timeout signals its
// child and then its own process group, so a job got two SIGTERMs microseconds apart and ended
// at once, its frame half written (found by a soak test: 1 run in 18; under mpirun 1 in 6).
std::atomic<int64_t> g_noted_ns{0};
constexpr int64_t kRepeatWindowNs = 250'000'000;
static_assert(std::atomic<int64_t>::is_always_lock_free);

int64_t NowNs() {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);  // async-signal-safe
  return int64_t{t.tv_sec} * 1'000'000'000 + t.tv_nsec;
}
static_assert(std::atomic<int>::is_always_lock_free && std::atomic<bool>::is_always_lock_free);

extern "C" void NoteInterrupt(int sig) {
  if (g_signal.load() == sig && NowNs() - g_noted_ns.load() < kRepeatWindowNs) return;
  if (g_signal.load() != 0 || !g_hold.load()) {  // the default action, now
    std::signal(sig, SIG_DFL);
    std::raise(sig);
    return;
  }
  g_noted_ns.store(NowNs());
  g_signal.store(sig);
  if (g_announce.load()) {
    constexpr char kText[] =
        "\nraystack render: interrupted: keeping what can be kept (once more to end at once)\n";
    const int skip = g_after_bar.load() ? 0 : 1;
    (void)!write(STDERR_FILENO, kText + skip, sizeof kText - 1 - skip);  // async-signal-safe, unlike stdio
  }
}

}  // namespace

void CatchInterrupts(bool announce) {
  g_announce.store(announce);
  g_after_bar.store(::isatty(STDERR_FILENO) == 1);
  struct sigaction action {};
  action.sa_handler = NoteInterrupt;
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_RESTART;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  if (!IgnoredByTheCaller(SIGHUP)) sigaction(SIGHUP, &action, nullptr);
}

bool IgnoredByTheCaller(int signal) {
  struct sigaction now {};
  return sigaction(signal, nullptr, &now) == 0 && now.sa_handler == SIG_IGN;
}

void HoldInterrupts(bool hold) { g_hold.store(hold); }

int InterruptSignal() { return g_signal.load(); }

const char* InterruptName(int signal) {
  switch (signal) {
    case SIGINT: return "SIGINT";
    case SIGHUP: return "SIGHUP";
    default: return "SIGTERM";
  }
}

const char* InterruptCause(int signal) {
  return signal == SIGHUP ? "SIGHUP: the terminal or ssh session that started the job closed; a "
                            "long job outlives it under nohup, setsid, tmux or screen, or a "
                            "scheduler"
                          : "";
}

}  // namespace raystack
