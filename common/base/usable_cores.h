#pragma once
// The cores this process may run on: its CPU affinity mask (taskset, mpirun's or srun's
// binding, a cpuset), not the machine's count. A rank that mpirun bound to one core ran as many
// ray threads as the machine has cores, time-sharing that one core (0.6-0.7x the speed).

namespace raystack {

// At least 1; the machine's count when the mask cannot be read.
int UsableCores();

}  // namespace raystack
