#include "common/base/interrupt.h"

#include <unistd.h>

#include <atomic>
#include <csignal>

namespace raystack {
namespace {

// Read by other threads: atomics, lock-free so that the handler may touch them.
std::atomic<int> g_signal{0};
std::atomic<bool> g_hold{false};
std::atomic<bool> g_announce{false};
// The announcement starts a line of its own after a progress bar (a terminal's, redrawn in
// place); in a log, where progress comes in whole lines, it had a blank line before it.
std::atomic<bool> g_after_bar{false};
static_assert(std::atomic<int>::is_always_lock_free && std::atomic<bool>::is_always_lock_free);

extern "C" void NoteInterrupt(int sig) {
  if (g_signal.load() != 0 || !g_hold.load()) {  // the default action, now
    std::signal(sig, SIG_DFL);
    std::raise(sig);
    return;
  }
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
