#pragma once
// SIGINT and SIGTERM (Ctrl-C; Slurm at a job's time limit, which reaches the ranks through
// mpirun, and mpirun sends SIGKILL about a second later), once CatchInterrupts has run:
// - while interrupts are held (HoldInterrupts: the master while a frame renders, a slave
//   always) the signal is noted, not fatal: the master then writes the frame's samples so far
//   for --resume before it ends (master/frame_steps.h), and a slave waits a moment for the
//   master's end of the job (slave_node.cpp);
// - otherwise, and at the second signal, the process ends at once, as the default action
//   would.

namespace raystack {

// `announce`: say on stderr, from the handler, that the signal was noted.
void CatchInterrupts(bool announce);
void HoldInterrupts(bool hold);
// The signal noted (SIGINT or SIGTERM), or 0.
int InterruptSignal();
// "SIGINT" or "SIGTERM", for messages.
const char* InterruptName(int signal);

}  // namespace raystack
