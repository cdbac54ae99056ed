// WideBvh's walks compiled for the build's baseline: SSE2 on x86-64 (wide_bvh_walk_copies.h).

#include "common/geometry/wide_bvh_walk_copies.h"

#define RAYSTACK_WALK_COPY walks_baseline
#define RAYSTACK_WALK_AVX2 0
#include "common/geometry/wide_bvh_walk_copy.inc"
