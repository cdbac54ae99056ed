#pragma once
// The common tail of every reader: counts triangles, drops zero-area ones (counted, not sent),
// tracks bounds and attribute presence, and hands triangles to the sink in fixed-size batches
// so the sink pays one virtual call per batch.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "tools/import/model_reader.h"
#include "tools/import/polygon_split.h"

namespace raystack::import {

// One corner of a polygon, attributes already fetched from the vertex tables.
struct FaceCorner {
  Vec3f p;
  Vec3f n;
  float uv[2] = {0, 0};
  bool has_normal = false;
  bool has_uv = false;
};

class TriangleBatcher {
 public:
  static constexpr size_t kBatchTriangles = 4096;

  // `sink` and `info` must outlive the batcher; `max_triangles` caps ModelInfo::triangles.
  TriangleBatcher(TriangleSink& sink, ModelInfo* info, uint64_t max_triangles);

  // True when `count` more triangles would pass the cap (the reader reports where).
  bool WouldExceedLimit(uint64_t count) const {
    return count > max_triangles_ || info_->triangles > max_triangles_ - count;
  }
  uint64_t max_triangles() const { return max_triangles_; }
  // Counts the triangle and queues it unless its area is zero; sends a full batch.
  Status Add(const SourceTriangle& triangle);
  // Splits a face of n >= 3 corners into n - 2 triangles (PolygonSplitter), each via Add().
  Status AddPolygon(std::span<const FaceCorner> corners, uint32_t material);
  // Sends what is queued and logs how many zero-area triangles were dropped from `path`.
  Status Finish(const std::string& path);

 private:
  Status Flush();

  TriangleSink& sink_;
  ModelInfo* info_;
  uint64_t max_triangles_;
  std::vector<SourceTriangle> batch_;
  PolygonSplitter splitter_;
  std::vector<Vec3f> positions_;  // of the face being split
  std::vector<PolygonSplitter::Triangle> split_;
  uint64_t fanned_concave_ = 0;  // faces too large to clip, split as fans
};

}  // namespace raystack::import
