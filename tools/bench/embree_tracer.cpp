#include "tools/bench/embree_tracer.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>

namespace raystack::bench {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

void SetRay(const Ray& r, RTCRay* out) {
  out->org_x = r.origin.x;
  out->org_y = r.origin.y;
  out->org_z = r.origin.z;
  out->tnear = r.tmin;
  out->dir_x = r.direction.x;
  out->dir_y = r.direction.y;
  out->dir_z = r.direction.z;
  out->time = 0;
  out->tfar = r.tmax;
  out->mask = 0xffffffffu;
  out->id = 0;
  out->flags = 0;
}

// Packet of N rays in Embree's SoA layout, filled from rays [0, count) (count <= N).
template <int N, typename RayHitN, typename RayN>
void SetPacket(std::span<const Ray> rays, RayN* p, int* valid) {
  for (int k = 0; k < N; ++k) {
    const bool on = k < static_cast<int>(rays.size());
    valid[k] = on ? -1 : 0;
    const Ray r = on ? rays[static_cast<size_t>(k)] : Ray{};
    p->org_x[k] = r.origin.x;
    p->org_y[k] = r.origin.y;
    p->org_z[k] = r.origin.z;
    p->tnear[k] = r.tmin;
    p->dir_x[k] = r.direction.x;
    p->dir_y[k] = on ? r.direction.y : 1.0f;
    p->dir_z[k] = r.direction.z;
    p->time[k] = 0;
    p->tfar[k] = r.tmax;
    p->mask[k] = 0xffffffffu;
    p->id[k] = 0;
    p->flags[k] = 0;
  }
}

// What a closest-hit query hands back, in the record ours fills (raystack::Hit: distance,
// barycentrics, triangle and geometry ids), so both sides of the comparison write the same bytes.
Hit HitOf(float tfar, float u, float v, unsigned prim_id, unsigned geom_id) {
  if (geom_id == RTC_INVALID_GEOMETRY_ID) return Hit{kInf};
  return Hit{tfar, u, v, prim_id, geom_id, kInvalidId};
}

template <int N, typename RayHitN>
void IntersectPackets(RTCScene scene, RTCIntersectContext* ctx, std::span<const Ray> rays,
                      std::span<Hit> hits) {
  alignas(64) RayHitN p;
  alignas(64) int valid[N];
  for (size_t i = 0; i < rays.size(); i += N) {
    const size_t n = std::min<size_t>(N, rays.size() - i);
    SetPacket<N, RayHitN>(rays.subspan(i, n), &p.ray, valid);
    for (int k = 0; k < N; ++k) p.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
    if constexpr (N == 4) rtcIntersect4(valid, scene, ctx, &p);
    if constexpr (N == 8) rtcIntersect8(valid, scene, ctx, &p);
    if constexpr (N == 16) rtcIntersect16(valid, scene, ctx, &p);
    for (size_t k = 0; k < n; ++k)
      hits[i + k] = HitOf(p.ray.tfar[k], p.hit.u[k], p.hit.v[k], p.hit.primID[k], p.hit.geomID[k]);
  }
}

template <int N, typename RayN>
void OccludedPackets(RTCScene scene, RTCIntersectContext* ctx, std::span<const Ray> rays,
                     std::span<uint8_t> occluded) {
  alignas(64) RayN p;
  alignas(64) int valid[N];
  for (size_t i = 0; i < rays.size(); i += N) {
    const size_t n = std::min<size_t>(N, rays.size() - i);
    SetPacket<N, RayN>(rays.subspan(i, n), &p, valid);
    if constexpr (N == 4) rtcOccluded4(valid, scene, ctx, &p);
    if constexpr (N == 8) rtcOccluded8(valid, scene, ctx, &p);
    if constexpr (N == 16) rtcOccluded16(valid, scene, ctx, &p);
    for (size_t k = 0; k < n; ++k) occluded[i + k] = p.tfar[k] == -kInf ? 1 : 0;
  }
}

// Streams go through a fixed stack buffer of this many rays (Embree's own examples use
// streams of a few hundred to a few thousand rays).
constexpr size_t kStream = 256;

}  // namespace

const char* EmbreeApiName(EmbreeApi api) {
  switch (api) {
    case EmbreeApi::kSingle: return "rtcIntersect1";
    case EmbreeApi::kPacket4: return "rtcIntersect4";
    case EmbreeApi::kPacket8: return "rtcIntersect8";
    case EmbreeApi::kPacket16: return "rtcIntersect16";
    case EmbreeApi::kStream: return "rtcIntersect1M";
  }
  return "?";
}

EmbreeTracer::EmbreeTracer(std::span<const Vec3f> vertices, int build_threads, bool robust) {
  const std::string config = "threads=" + std::to_string(build_threads);
  device_ = rtcNewDevice(config.c_str());
  if (!device_) {
    std::fprintf(stderr, "embree: rtcNewDevice failed (%d)\n", rtcGetDeviceError(nullptr));
    std::exit(1);
  }
  scene_ = rtcNewScene(device_);
  rtcSetSceneBuildQuality(scene_, RTC_BUILD_QUALITY_HIGH);
  rtcSetSceneFlags(scene_, robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
  RTCGeometry geometry = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
  rtcSetGeometryBuildQuality(geometry, RTC_BUILD_QUALITY_HIGH);
  const size_t n = vertices.size() / 3;
  auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
      geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 3 * n));
  auto* idx = static_cast<unsigned*>(rtcSetNewGeometryBuffer(
      geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), n));
  for (size_t i = 0; i < 3 * n; ++i) {
    v[3 * i] = vertices[i].x;
    v[3 * i + 1] = vertices[i].y;
    v[3 * i + 2] = vertices[i].z;
    idx[i] = static_cast<unsigned>(i);
  }
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(scene_, geometry);
  rtcReleaseGeometry(geometry);
  rtcCommitScene(scene_);
}

EmbreeTracer::~EmbreeTracer() {
  rtcReleaseScene(scene_);
  rtcReleaseDevice(device_);
}

bool EmbreeTracer::Supports(EmbreeApi api) const {
  switch (api) {
    case EmbreeApi::kSingle: return true;
    case EmbreeApi::kPacket4: return rtcGetDeviceProperty(device_, RTC_DEVICE_PROPERTY_NATIVE_RAY4_SUPPORTED) != 0;
    case EmbreeApi::kPacket8: return rtcGetDeviceProperty(device_, RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED) != 0;
    case EmbreeApi::kPacket16: return rtcGetDeviceProperty(device_, RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED) != 0;
    case EmbreeApi::kStream: return rtcGetDeviceProperty(device_, RTC_DEVICE_PROPERTY_RAY_STREAM_SUPPORTED) != 0;
  }
  return false;
}

std::string EmbreeTracer::Version() const {
  const char* version = "3";
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%s.%ld.%ld", version,
                static_cast<long>(rtcGetDeviceProperty(device_, RTC_DEVICE_PROPERTY_VERSION_MINOR)),
                static_cast<long>(rtcGetDeviceProperty(device_, RTC_DEVICE_PROPERTY_VERSION_PATCH)));
  return buffer;
}

void EmbreeTracer::Intersect(EmbreeApi api, bool coherent, std::span<const Ray> rays,
                             std::span<Hit> hits) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
  switch (api) {
    case EmbreeApi::kSingle:
      for (size_t i = 0; i < rays.size(); ++i) {
        RTCRayHit rh;
        SetRay(rays[i], &rh.ray);
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(scene_, &ctx, &rh);
        hits[i] = HitOf(rh.ray.tfar, rh.hit.u, rh.hit.v, rh.hit.primID, rh.hit.geomID);
      }
      return;
    case EmbreeApi::kPacket4: return IntersectPackets<4, RTCRayHit4>(scene_, &ctx, rays, hits);
    case EmbreeApi::kPacket8: return IntersectPackets<8, RTCRayHit8>(scene_, &ctx, rays, hits);
    case EmbreeApi::kPacket16: return IntersectPackets<16, RTCRayHit16>(scene_, &ctx, rays, hits);
    case EmbreeApi::kStream: {
      RTCRayHit stream[kStream];
      for (size_t i = 0; i < rays.size(); i += kStream) {
        const size_t n = std::min(kStream, rays.size() - i);
        for (size_t k = 0; k < n; ++k) {
          SetRay(rays[i + k], &stream[k].ray);
          stream[k].hit.geomID = RTC_INVALID_GEOMETRY_ID;
        }
        rtcIntersect1M(scene_, &ctx, stream, static_cast<unsigned>(n), sizeof(RTCRayHit));
        for (size_t k = 0; k < n; ++k) {
          const RTCRayHit& r = stream[k];
          hits[i + k] = HitOf(r.ray.tfar, r.hit.u, r.hit.v, r.hit.primID, r.hit.geomID);
        }
      }
      return;
    }
  }
}

void EmbreeTracer::Occluded(EmbreeApi api, bool coherent, std::span<const Ray> rays,
                            std::span<uint8_t> occluded) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
  switch (api) {
    case EmbreeApi::kSingle:
      for (size_t i = 0; i < rays.size(); ++i) {
        RTCRay r;
        SetRay(rays[i], &r);
        rtcOccluded1(scene_, &ctx, &r);
        occluded[i] = r.tfar == -kInf ? 1 : 0;
      }
      return;
    case EmbreeApi::kPacket4: return OccludedPackets<4, RTCRay4>(scene_, &ctx, rays, occluded);
    case EmbreeApi::kPacket8: return OccludedPackets<8, RTCRay8>(scene_, &ctx, rays, occluded);
    case EmbreeApi::kPacket16: return OccludedPackets<16, RTCRay16>(scene_, &ctx, rays, occluded);
    case EmbreeApi::kStream: {
      RTCRay stream[kStream];
      for (size_t i = 0; i < rays.size(); i += kStream) {
        const size_t n = std::min(kStream, rays.size() - i);
        for (size_t k = 0; k < n; ++k) SetRay(rays[i + k], &stream[k]);
        rtcOccluded1M(scene_, &ctx, stream, static_cast<unsigned>(n), sizeof(RTCRay));
        for (size_t k = 0; k < n; ++k) occluded[i + k] = stream[k].tfar == -kInf ? 1 : 0;
      }
      return;
    }
  }
}

}  // namespace raystack::bench
