#pragma once
// The options of `raystack render SCENE.json [options]`: what they hold, their usage text, and
// parsing them (each value checked against its range, every error naming the option).

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "common/base/log.h"
#include "common/base/status.h"
#include "master/convergence_monitor.h"
#include "master/preview/live_preview.h"
#include "slave/block_loader.h"
#include "slave/direct_reads.h"
#include "slave/render_engine.h"

namespace raystack::master {

extern const char* const kRenderUsage;
// kRenderUsage with the folder of the installed documents: share/doc/raystack/ beside this
// program's bin/ (wherever it was installed: /usr, /opt/raystack, ...), else /usr/share/doc's.
std::string RenderUsage();

struct RenderArgs {
  std::string scene;
  slave::EngineOptions engine;
  int tile_size = 32;
  std::string output;
  bool png = true;
  float exposure = 0;
  std::string stats;
  bool quiet = false;
  double checkpoint_s = 0;
  std::string blocks = "auto";
  std::string coarse_rounds = "auto";  // --coarse-rounds
  slave::DirectIo direct_io = slave::DirectIo::kAuto;
  uint32_t spp = 0;       // 0: the scene's
  uint32_t pass_spp = 0;  // 0: doubling passes
  StopRules stop;
  std::string convergence_log;
  double log_interval_s = 0.5;
  std::string reference;
  double lost_after_s = 5;
  bool resume = false;
  int fault_rank = 0;  // 0: every slave
  int64_t kill_after_tiles = -1;
  int64_t stall_after_tiles = -1;
  double stall_s = 5;
  int64_t fail_read = -1;
  int64_t kill_after_checkpoints = -1;
  int64_t fail_checkpoints = 0;
  // --frames A-B: the cameras rendered, first and last (inclusive); the files keep their numbers.
  size_t first_frame = 0, last_frame = SIZE_MAX;
  int64_t fail_writes = 0;  // --fault-fail-writes: the first N frame images fail to write
  double slow_writes_s = 0;  // --fault-slow-writes: each frame image's write waits S first
  preview::LivePreviewOptions preview;
  // Options given that only slaves of a distributed job use (--blocks, --lost-after, the
  // slaves' faults), for a warning when one process renders alone.
  std::vector<std::string> slave_options;
  bool threads_given = false;  // --threads: no word about cores its default would leave idle
};

// --threads' default: every core, up to the most ray threads the loader can serve
// (BlockLoader::kMaxRayThreads), so that a node with more cores than that still renders.
inline int DefaultRayThreads(unsigned cores) {
  return static_cast<int>(
      std::clamp(cores, 1u, static_cast<unsigned>(slave::BlockLoader::kMaxRayThreads)));
}

// What to say when --threads' default (64 at most) leaves cores idle, or "": this process may
// use `usable` of the machine's `machine` cores, and `slaves_here` slaves render on the machine
// (1 alone). Slaves bound to shares apart (their shares add up to no more than the machine) are
// told each of its own; unbound ones (each may use every core) of the machine's.
inline std::string RayThreadsCapNote(unsigned usable, unsigned machine, int slaves_here) {
  const auto most = static_cast<uint64_t>(slave::BlockLoader::kMaxRayThreads);
  const auto slaves = static_cast<uint64_t>(std::max(slaves_here, 1));
  if (usable <= most) return "";
  const uint64_t advice = (usable + most - 1) / most;
  if (slaves > 1 && usable * slaves > machine) {  // unbound: each sees the whole machine
    if (usable <= slaves * most) return "";
    return StrFormat("the %llu slaves on this machine may each use all of its %u cores and run at "
                     "most %llu ray threads each: run %llu or more slaves on it, each bound to its "
                     "share of the cores (e.g. mpirun --map-by socket --bind-to socket), to use "
                     "them all", static_cast<unsigned long long>(slaves), usable,
                     static_cast<unsigned long long>(most), static_cast<unsigned long long>(advice));
  }
  return StrFormat("this process may use %u cores and renders with %llu ray threads, the most one "
                   "slave runs: run %llu or more slaves for these cores, each bound to its share "
                   "(e.g. mpirun --map-by socket --bind-to socket), to use them all",
                   usable, static_cast<unsigned long long>(most),
                   static_cast<unsigned long long>(advice * slaves));
}

// Logs RayThreadsCapNote for this process and machine, if it has anything to say.
void WarnOfIdleCores(int slaves_here);

// Fills `a` from the command line; `*help` is set by -h/--help (then nothing else is checked).
Status ParseRenderArgs(int argc, char** argv, RenderArgs* a, bool* help);

}  // namespace raystack::master
