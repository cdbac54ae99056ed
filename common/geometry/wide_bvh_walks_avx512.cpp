// WideBvh's walks: the AVX2 code (8 lanes a register) compiled with AVX-512's instructions
// allowed (wide_bvh_walk_copies.h), for CPUs with AVX-512 F, VL, DQ and BW (which all have BMI,
// BMI2 and FMA: allowed too). GCC then keeps comparisons in mask registers and has 32 vector
// registers rather than 16 (measured in wide_bvh_walks.cpp). With AVX-512 alone, without BMI,
// it was no faster than the AVX2 copy. Packets in one 16-lane register were tried and were no
// faster than two registers of 8 lanes on AMD Zen 4, which runs 512-bit operations as two
// halves. (GCC still copies a few 64-byte stack arrays with zmm moves.)

#include "common/geometry/wide_bvh_walk_copies.h"

#if RAYSTACK_HAS_WALK_AVX2
#pragma GCC push_options
#pragma GCC target("avx2,bmi,bmi2,fma,avx512f,avx512vl,avx512dq,avx512bw")  // CpuWalkIsa checks each
#define RAYSTACK_WALK_COPY walks_avx512
#define RAYSTACK_WALK_AVX2 1
#include "common/geometry/wide_bvh_walk_copy.inc"
#pragma GCC pop_options
#endif
