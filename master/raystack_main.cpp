// raystack: the renderer. One executable for every role; `mpirun` will launch it too.

#include <csignal>
#include <cstdio>
#include <cstring>
#include <new>
#include <system_error>

#include "common/base/build_id.h"
#include "common/base/standard_streams.h"
#include "master/render_command.h"

namespace {

constexpr const char* kUsage = R"(usage: raystack COMMAND [options]

commands:
  render SCENE.json   render a block store as the scene file says (raystack render --help)
  --version           this build's version and git commit (every rank of a job must match)

Stores are made with raystack-prep and inspected with raystack-info.
)";

}  // namespace

int main(int argc, char** argv) {
  raystack::OpenClosedStandardStreams();
  // Progress lines reach a log file (Slurm's, a redirect) as they are printed, not at exit.
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  if (argc >= 2 && std::strcmp(argv[1], "render") == 0) {
    // `raystack render --version` as `raystack --version` (it was an unknown option).
    for (int i = 2; i < argc; ++i)
      if (std::strcmp(argv[i], "--version") == 0) {
        std::printf("raystack %s\n", raystack::BuildId());
        return raystack::EndWithStandardOutput("raystack", 0);
      }
    // A reader that went away (`--stats /dev/stdout | head`, a closed terminal) is a failed write,
    // said and survived: its signal ended the render mid-sequence, the output's lock left.
    std::signal(SIGPIPE, SIG_IGN);
    try {
      return raystack::master::RenderCommand(argc - 1, argv + 1);
    } catch (const std::bad_alloc&) {  // memory is checked up front; this is the last resort
      std::fputs("raystack render: out of memory (a smaller image, --cache-mb or fewer threads "
                 "may fit)\n", stderr);
      return 1;
    } catch (const std::system_error& e) {  // a thread refused: ulimit -u, -v
      std::fprintf(stderr, "raystack render: cannot start a thread (%s): a limit on threads or "
                   "address space (ulimit -u, -v)?\n", e.what());
      return 1;
    }
  }
  if (argc >= 2 && (std::strcmp(argv[1], "-h") == 0 || std::strcmp(argv[1], "--help") == 0)) {
    std::fputs(kUsage, stdout);
    return raystack::EndWithStandardOutput("raystack", 0);
  }
  if (argc >= 2 && std::strcmp(argv[1], "--version") == 0) {
    std::printf("raystack %s\n", raystack::BuildId());
    return raystack::EndWithStandardOutput("raystack", 0);
  }
  if (argc >= 2) std::fprintf(stderr, "raystack: unknown command '%s'\n", argv[1]);
  std::fputs(kUsage, stderr);
  return 2;
}
