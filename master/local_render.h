#pragma once
// `raystack render` in one process (no mpirun, or mpirun -np 1): the process plays master and
// slave, its render engine's ray threads feeding the film directly.

#include "common/base/status.h"
#include "master/render_args.h"

namespace raystack::master {

Status RenderLocally(const RenderArgs& args);

}  // namespace raystack::master
