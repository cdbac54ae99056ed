#pragma once
// The ray sets every in-core throughput benchmark uses, so our tracer and Embree see exactly
// the same rays: primary rays of a pinhole camera (in 4x4 pixel tiles, so 4, 8 or 16
// consecutive rays form a coherent packet), shadow rays from the primary hits to a point
// light, and incoherent rays (random origins in the model's box, random directions).

#include <chrono>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include "common/geometry/bounds.h"
#include "common/geometry/ray.h"

namespace raystack::bench {

struct Camera {
  Vec3f eye, forward, right, up;
  float tan_half = 0.5f;
};

// Looks at the model's centre from a diagonal, close enough that the model fills most of
// the frame (so primary rays mostly hit, as in a real render).
Camera FrameModel(const Bounds3f& model);

// width * height rays (both multiples of 4), tile by tile: 16 consecutive rays are a 4x4 tile.
std::vector<Ray> PrimaryRays(const Camera& camera, int width, int height);

// One shadow ray per primary ray that hit: from its hit point towards `light`, any hit in
// (1e-4, 1 - 1e-4) along the segment (the offsets keep both ends off the surfaces).
std::vector<Ray> ShadowRays(std::span<const Ray> primary, std::span<const Hit> hits, Vec3f light);

// A point light above and in front of the model.
Vec3f LightFor(const Bounds3f& model, const Camera& camera);

// n rays with origins uniform in `model` and directions uniform in [-1, 1]^3 (seeded).
std::vector<Ray> RandomRays(const Bounds3f& model, int n, uint32_t seed);

// Calls fn(begin, end, thread) over [0, n) in chunks of `chunk`, handed out dynamically to
// `threads` threads (the calling thread is one of them).
void ParallelChunks(int threads, size_t n, size_t chunk,
                    const std::function<void(size_t, size_t, int)>& fn);

// Runs fn `repeats` times and returns the median time in seconds: wall time, or with
// `cpu_time` the process's CPU time (summed over threads; steadier on a shared machine,
// for comparing code changes with one thread).
double MedianSeconds(int repeats, const std::function<void()>& fn, bool cpu_time = false);

}  // namespace raystack::bench
