#include "tools/prep/interrupt_cleanup.h"

#include <pthread.h>
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstdio>
#include <map>
#include <mutex>
#include <thread>

#include "common/base/interrupt.h"

namespace raystack::prep {
namespace {

std::mutex g_mu;  // held by a running clean-up to the process's end
std::map<uint64_t, std::function<std::string()>> g_cleanups;
uint64_t g_next_id = 0;
std::atomic<bool> g_store_written{false};

}  // namespace

void CleanUpOnInterrupt(const std::string& output) {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  if (!IgnoredByTheCaller(SIGHUP)) sigaddset(&set, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  std::thread([set, output] {
    int sig = 0;
    if (sigwait(&set, &sig) != 0) return;
    const char* name = InterruptName(sig);
    std::fflush(stdout);
    std::fprintf(stderr, "\nraystack-prep: interrupted (%s): removing what this conversion wrote\n", name);
    if (*InterruptCause(sig)) std::fprintf(stderr, "raystack-prep: %s\n", InterruptCause(sig));
    const std::lock_guard lock(g_mu);
    std::string left;
    for (auto& [id, clean] : g_cleanups) {
      const std::string what = clean();
      if (!what.empty()) left += "; " + what;
    }
    if (g_store_written.load())
      std::fprintf(stderr, "raystack-prep: interrupted (%s) as the conversion ended: %s holds the "
                   "new store, complete%s\n", name, output.c_str(), left.c_str());
    else
      std::fprintf(stderr, "raystack-prep: interrupted (%s): %s is as it was before this run (a "
                   "store there is kept whole; a folder this run made is removed)%s; run the "
                   "same command again to convert\n", name, output.c_str(),
                   left.empty() ? ", and its temporary files are gone" : left.c_str());
    std::fflush(nullptr);
    _exit(128 + sig);
  }).detach();
}

void NoteStoreWritten() { g_store_written = true; }

OnInterrupt::OnInterrupt(std::function<std::string()> clean) {
  const std::lock_guard lock(g_mu);
  id_ = g_next_id++;
  g_cleanups.emplace(id_, std::move(clean));
}

OnInterrupt::~OnInterrupt() {
  const std::lock_guard lock(g_mu);
  g_cleanups.erase(id_);
}

}  // namespace raystack::prep
