#pragma once
// SIGINT, SIGTERM and SIGHUP (Ctrl-C; Slurm at a job's time limit, which reaches the ranks
// through mpirun, and mpirun sends SIGKILL about a second later; the terminal or ssh session
// closed, which ended a job with nothing written, found by a pipeline review), once
// CatchInterrupts has run:
// - while interrupts are held (HoldInterrupts: the master while a frame renders, a slave
//   always) the signal is noted, not fatal: the master then writes the frame's samples so far
//   for --resume before it ends (master/frame_steps.h), and a slave waits a moment for the
//   master's end of the job (slave_node.cpp);
// - otherwise, and at the second signal, the process ends at once, as the default action
//   would; the same signal again within a quarter of a second is taken for the same sending
//   (GNU timeout sends two SIGTERMs at once), not a second one.

namespace raystack {

// `announce`: say on stderr, from the handler, that the signal was noted. SIGHUP is left as it
// is when ignored (nohup: the user's choice).
void CatchInterrupts(bool announce);
void HoldInterrupts(bool hold);
// The signal noted (SIGINT, SIGTERM or SIGHUP), or 0.
int InterruptSignal();
// "SIGINT", "SIGTERM" or "SIGHUP", for messages.
const char* InterruptName(int signal);
// What sent a SIGHUP and how a job outlives it; "" for the others.
const char* InterruptCause(int signal);
// Whether `signal` is ignored now (SIG_IGN: as nohup leaves SIGHUP; asked before
// CatchInterrupts sets its handler).
bool IgnoredByTheCaller(int signal);

}  // namespace raystack
