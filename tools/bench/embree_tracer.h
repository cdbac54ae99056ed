#pragma once
// The same mesh in Embree 3, traced with each of its ray APIs (single rays, packets of 4, 8
// and 16, and streams), so the benchmark can report the best Embree figure. Settings as
// asked for a fair comparison: build quality high, robust mode off, one triangle geometry.
// Results are reduced to what the comparison checks: the hit distance (infinity for a
// miss) or the occlusion flag.

#include <embree3/rtcore.h>

#include <span>
#include <string>
#include <vector>

#include "common/geometry/ray.h"
#include "common/geometry/vec.h"

namespace raystack::bench {

enum class EmbreeApi { kSingle, kPacket4, kPacket8, kPacket16, kStream };
const char* EmbreeApiName(EmbreeApi api);

class EmbreeTracer {
 public:
  // `vertices` holds 3 points per triangle. `build_threads` only affects the build.
  EmbreeTracer(std::span<const Vec3f> vertices, int build_threads);
  ~EmbreeTracer();
  EmbreeTracer(const EmbreeTracer&) = delete;
  EmbreeTracer& operator=(const EmbreeTracer&) = delete;

  // Whether this Embree was built with the packet/stream API `api`.
  bool Supports(EmbreeApi api) const;
  std::string Version() const;

  // Closest hit distances (infinity for a miss) of rays[i], i in [0, n). `coherent` sets the
  // context flag Embree uses to pick its stream traversal.
  void Intersect(EmbreeApi api, bool coherent, std::span<const Ray> rays, std::span<float> t) const;
  // Any hit: occluded[i] = 1 when something lies in (tmin, tmax).
  void Occluded(EmbreeApi api, bool coherent, std::span<const Ray> rays,
                std::span<uint8_t> occluded) const;

 private:
  RTCDevice device_ = nullptr;
  RTCScene scene_ = nullptr;
};

}  // namespace raystack::bench
