#pragma once
// The same mesh in Embree 3, traced with each of its ray APIs (single rays, packets of 4, 8
// and 16, and streams), so the benchmark can report the best Embree figure. Settings: build
// quality high, one triangle geometry, robust mode off (Embree's fastest) unless asked for.
// A closest hit comes back as the record ours fills (raystack::Hit: distance, infinity for a
// miss, barycentrics, Embree's primitive and geometry ids), so both sides write the same bytes
// per ray; an any-hit query as the occlusion flag.

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
  // `vertices` holds 3 points per triangle. `build_threads` only affects the build. `robust`:
  // RTC_SCENE_FLAG_ROBUST (watertight triangle tests).
  EmbreeTracer(std::span<const Vec3f> vertices, int build_threads, bool robust = false);
  ~EmbreeTracer();
  EmbreeTracer(const EmbreeTracer&) = delete;
  EmbreeTracer& operator=(const EmbreeTracer&) = delete;

  // Whether this Embree was built with the packet/stream API `api`.
  bool Supports(EmbreeApi api) const;
  std::string Version() const;

  // Closest hits of rays[i], i in [0, n) (Hit::t infinity for a miss). `coherent` sets the
  // context flag Embree uses to pick its stream traversal.
  void Intersect(EmbreeApi api, bool coherent, std::span<const Ray> rays, std::span<Hit> hits) const;
  // Any hit: occluded[i] = 1 when something lies in (tmin, tmax).
  void Occluded(EmbreeApi api, bool coherent, std::span<const Ray> rays,
                std::span<uint8_t> occluded) const;

 private:
  RTCDevice device_ = nullptr;
  RTCScene scene_ = nullptr;
};

}  // namespace raystack::bench
