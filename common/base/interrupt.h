#pragma once
// SIGINT and SIGTERM (Ctrl-C; Slurm at a job's time limit, which reaches the ranks through
// mpirun, and mpirun sends SIGKILL about a second later) are noted, not fatal, once
// CatchInterrupts has run: the master then writes the frame's samples so far for --resume
// before it ends (render_command.cpp). A second one ends the process at once, as the default
// action would.

namespace raystack {

void CatchInterrupts();
// The signal noted (SIGINT or SIGTERM), or 0.
int InterruptSignal();

}  // namespace raystack
