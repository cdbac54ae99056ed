#pragma once
// `raystack render` under mpirun with more than one rank: rank 0 is the master (tiles, film,
// output), ranks 1..N the slaves (a render engine each). Every rank reads the scene file; only
// the slaves need the store.

#include "common/base/status.h"
#include "common/transport/transport.h"
#include "master/render_args.h"

namespace raystack::master {

// This rank's part of the job over `net`.
Status RenderDistributed(const RenderArgs& args, transport::Transport* net);

}  // namespace raystack::master
