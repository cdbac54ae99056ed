// WideBvh's walks compiled for AVX2 (wide_bvh_walk_copies.h): a node's 8 boxes, and 8 rays of a
// packet, in one register where SSE2 needs two.

#include "common/geometry/wide_bvh_walk_copies.h"

#if RAYSTACK_HAS_WALK_AVX2
#pragma GCC push_options
#pragma GCC target("avx2")
#define RAYSTACK_WALK_COPY walks_avx2
#define RAYSTACK_WALK_AVX2 1
#include "common/geometry/wide_bvh_walk_copy.inc"
#pragma GCC pop_options
#endif
