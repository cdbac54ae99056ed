#include "common/base/interrupt.h"

#include <csignal>

namespace raystack {
namespace {

volatile std::sig_atomic_t g_signal = 0;

extern "C" void NoteInterrupt(int sig) {
  if (g_signal != 0) {  // the second: the default action, now
    std::signal(sig, SIG_DFL);
    std::raise(sig);
    return;
  }
  g_signal = sig;
}

}  // namespace

void CatchInterrupts() {
  struct sigaction action {};
  action.sa_handler = NoteInterrupt;
  sigemptyset(&action.sa_mask);
  action.sa_flags = SA_RESTART;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

int InterruptSignal() { return g_signal; }

}  // namespace raystack
