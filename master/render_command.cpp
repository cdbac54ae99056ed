#include "master/render_command.h"

#include <cstdio>

#include "common/base/interrupt.h"
#include "common/base/log.h"
#include "common/mpi/mpi_transport.h"
#include "master/distributed_render.h"
#include "master/local_render.h"
#include "master/render_args.h"

namespace raystack::master {
namespace {

// A job that fails after SIGINT or SIGTERM was noted (a frame's write given up by Ctrl-C, say)
// ends with the signal's code and says it was interrupted: it ended with 1 and no word of the
// interrupt, which a script took for a render error.
int FailureCode(const std::string& prefix, const std::string& message) {
  const int signal = InterruptSignal();
  if (signal == 0) {
    std::fprintf(stderr, "%s: %s\n", prefix.c_str(), message.c_str());
    return 1;
  }
  std::fprintf(stderr, "%s: interrupted (%s): %s\n", prefix.c_str(), InterruptName(signal),
               message.c_str());
  if (*InterruptCause(signal)) std::fprintf(stderr, "%s: %s\n", prefix.c_str(), InterruptCause(signal));
  return 128 + signal;
}

}  // namespace

int RenderCommand(int argc, char** argv) {
  RenderArgs args;
  bool help = false;
  Status s = ParseRenderArgs(argc, argv, &args, &help);
  if (help) {
    std::fputs(RenderUsage().c_str(), stdout);
    return 0;
  }
  if (!s.ok()) {
    std::fprintf(stderr, "raystack render: %s\n", s.message().c_str());
    return 2;
  }
  if (args.quiet) SetLogLevel(LogLevel::kWarning);  // -q: warnings and errors only
  if (mpi::LaunchedByMpirun()) {
    Expected<std::unique_ptr<mpi::MpiTransport>> net = mpi::MpiTransport::Init(&argc, &argv);
    if (!net.ok()) {
      std::fprintf(stderr, "raystack render: %s\n", net.status().message().c_str());
      return 1;
    }
    if ((*net)->size() > 1) {
      const int rank = (*net)->rank();
      // mpirun forwards SIGINT and SIGTERM to every rank, and SIGKILL a second later: a slave
      // that died of the signal at once had mpirun end the master before it wrote anything.
      // So a slave holds it while its node runs (SlaveNode: it waits for the master's end of
      // the job, or ends a moment later if the master was not signalled); the master holds it
      // from its first frame to its last write (EndInterrupted writes the frame).
      CatchInterrupts(rank == 0);
      if (rank > 0) args.quiet = true;  // the master reports
      s = RenderDistributed(args, net->get());
      int code = 0;
      if (!s.ok()) {
        const std::string prefix = "raystack render (rank " + std::to_string(rank) + ")";
        if (rank == 0) {
          code = FailureCode(prefix, s.message());
        } else {
          std::fprintf(stderr, "%s: %s\n", prefix.c_str(), s.message().c_str());
          code = 1;
        }
        // A slave whose master is gone ends alone (MPI_Abort could end a master that is only
        // cut off from this host, with its image nearly done).
        if (rank > 0 && (*net)->dead(0)) mpi::MpiTransport::ExitWithoutFinalize(1);
        // The master has ended the job on every rank; a slave whose master did not answer
        // ends it the hard way rather than leave the others waiting.
        if (rank > 0) (*net)->Abort(1);
      }
      // A rank that will not end with the job (another build's, one that did not acknowledge
      // the end) would keep mpirun waiting, under --enable-recovery forever.
      if ((*net)->rank_will_not_end()) (*net)->Abort(code);
      if ((*net)->rank_died()) mpi::MpiTransport::ExitWithoutFinalize(code);
      return code;
    }
    // mpirun -np 1: one process plays both roles, as without mpirun.
  }
  CatchInterrupts(true);
  s = RenderLocally(args);
  return s.ok() ? 0 : FailureCode("raystack render", s.message());
}

}  // namespace raystack::master
