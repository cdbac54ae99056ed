#pragma once
// One slot per sample in flight on a ray thread: which pixel and sample it is, how many of its
// rays are still alive, and its radiance so far as order-independent fixed-point sums (its
// shadow and bounce rays finish in any order). When the last ray ends, the slot closes into a
// SampleResult. Slots are recycled through a free list: no allocation per sample once warm.
// Owned by one ray thread; not thread-safe.

#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "common/base/check.h"
#include "common/render/fixed_sum.h"
#include "common/render/sample_result.h"
#include "common/geometry/vec.h"

namespace raystack::slave {

class SampleSlots {
 public:
  uint32_t Open(uint32_t pixel, uint32_t sample, uint32_t tile) {
    uint32_t id;
    if (free_.empty()) {
      id = static_cast<uint32_t>(slots_.size());
      slots_.emplace_back();
    } else {
      id = free_.back();
      free_.pop_back();
    }
    // Built in place, not assigned from a Slot{} on the stack: that copy's 16-byte loads met
    // the temporary's narrower stores still in flight (a failed forward on every sample).
    Slot& s = *std::construct_at(&slots_[id]);
    s.pixel = pixel;
    s.sample = sample;
    s.tile = tile;
    s.pending = 1;  // the primary ray
    ++open_;
    peak_open_ = std::max(peak_open_, open_);
    return id;
  }

  uint32_t tile(uint32_t id) const { return slots_[id].tile; }
  uint32_t pixel(uint32_t id) const { return slots_[id].pixel; }
  uint32_t sample(uint32_t id) const { return slots_[id].sample; }

  void AddRays(uint32_t id, uint32_t n) { slots_[id].pending += n; }
  void AddRadiance(uint32_t id, Vec3f c) {
    Slot& s = slots_[id];
    s.rgb[0].Add(c.x);
    s.rgb[1].Add(c.y);
    s.rgb[2].Add(c.z);
  }
  void SetPrimary(uint32_t id, bool hit, float z, Vec3f normal, Vec3f albedo) {
    render::SampleResult& p = slots_[id].primary;
    p.hit = hit ? 1 : 0;
    p.z = z;
    p.normal[0] = normal.x, p.normal[1] = normal.y, p.normal[2] = normal.z;
    p.albedo[0] = albedo.x, p.albedo[1] = albedo.y, p.albedo[2] = albedo.z;
  }

  // One ray of the sample ended. True when it was the last: `result` is then filled and the
  // slot freed.
  bool RayDone(uint32_t id, render::SampleResult* result) {
    Slot& s = slots_[id];
    CHECK(s.pending > 0);
    if (--s.pending > 0) return false;
    *result = s.primary;
    result->pixel = s.pixel;
    result->sample = s.sample;
    for (int c = 0; c < 3; ++c) result->rgb[c] = static_cast<float>(s.rgb[c].Value());
    free_.push_back(id);
    --open_;
    return true;
  }

  // Frees every slot for a new frame (the memory stays) and zeroes the peak.
  void Reset() {
    free_.clear();
    for (uint32_t id = static_cast<uint32_t>(slots_.size()); id-- > 0;) free_.push_back(id);
    open_ = 0;
    peak_open_ = 0;
  }

  uint64_t open() const { return open_; }
  uint64_t peak_open() const { return peak_open_; }

 private:
  struct Slot {
    render::FixedSum rgb[3];
    render::SampleResult primary{0, 0, {0, 0, 0}, std::numeric_limits<float>::infinity(),
                                 {0, 0, 0}, {0, 0, 0}, 0};
    uint32_t pixel = 0, sample = 0, tile = 0, pending = 0;
  };
  std::vector<Slot> slots_;
  std::vector<uint32_t> free_;
  uint64_t open_ = 0, peak_open_ = 0;
};

}  // namespace raystack::slave
