#include "tools/import/triangle_batcher.h"

#include "common/base/log.h"

namespace raystack::import {
namespace {

// Exactly zero in float: repeated or collinear corners. Such triangles can never be hit and
// would only cost the BVH build; tiny but non-zero ones are kept.
bool HasZeroArea(const SourceTriangle& t) {
  // Edges scaled first, so a tiny triangle (1e-30 across) is not taken for a flat one.
  const Vec3f c = Cross(ScaledToUnitRange(t.p[1] - t.p[0]), ScaledToUnitRange(t.p[2] - t.p[0]));
  return c.x == 0.0f && c.y == 0.0f && c.z == 0.0f;
}

}  // namespace

TriangleBatcher::TriangleBatcher(TriangleSink& sink, ModelInfo* info, uint64_t max_triangles)
    : sink_(sink), info_(info), max_triangles_(max_triangles) {
  batch_.reserve(kBatchTriangles);
}

Status TriangleBatcher::Add(const SourceTriangle& triangle) {
  ++info_->triangles;
  if (HasZeroArea(triangle)) {
    ++info_->zero_area_dropped;
    return OkStatus();
  }
  info_->has_normals |= triangle.has_normals;
  info_->has_uvs |= triangle.has_uvs;
  batch_.push_back(triangle);
  if (batch_.size() == kBatchTriangles) return Flush();
  return OkStatus();
}

Status TriangleBatcher::AddPolygon(std::span<const FaceCorner> corners, uint32_t material) {
  positions_.clear();
  for (const FaceCorner& c : corners) positions_.push_back(c.p);
  if (!splitter_.Split(positions_, &split_)) ++fanned_concave_;
  SourceTriangle triangle;
  triangle.material = material;
  for (const PolygonSplitter::Triangle& t : split_) {
    triangle.has_normals = triangle.has_uvs = true;
    for (int k = 0; k < 3; ++k) {
      const FaceCorner& c = corners[t[k]];
      triangle.p[k] = c.p;
      triangle.n[k] = c.n;
      triangle.uv[k][0] = c.uv[0];
      triangle.uv[k][1] = c.uv[1];
      triangle.has_normals &= c.has_normal;
      triangle.has_uvs &= c.has_uv;
    }
    RAYSTACK_RETURN_IF_ERROR(Add(triangle));
  }
  return OkStatus();
}

Status TriangleBatcher::Flush() {
  if (batch_.empty()) return OkStatus();
  Status status = sink_.Consume(batch_);
  batch_.clear();
  return status;
}

Status TriangleBatcher::Finish(const std::string& path) {
  RAYSTACK_RETURN_IF_ERROR(Flush());
  if (info_->zero_area_dropped > 0)
    LOG_WARNING("import", "%s: dropped %llu zero-area triangles (of %llu)", path.c_str(),
                static_cast<unsigned long long>(info_->zero_area_dropped),
                static_cast<unsigned long long>(info_->triangles));
  if (info_->faces_under_three_corners > 0)
    LOG_WARNING("import", "%s: skipped %llu faces of fewer than 3 corners (edges or points: no "
                "surface)", path.c_str(),
                static_cast<unsigned long long>(info_->faces_under_three_corners));
  if (info_->attributes_not_finite > 0)
    LOG_WARNING("import", "%s: %llu normals or texture coordinates are not finite floats (NaN, "
                "inf, -1.#IND, or beyond float range, as 1e50): the faces that use them are "
                "shaded without them", path.c_str(),
                static_cast<unsigned long long>(info_->attributes_not_finite));
  if (fanned_concave_ > 0)
    LOG_WARNING("import", "%s: %llu non-convex faces of more than %zu corners were split as "
                "fans from their first corner, which may cover their notches (split them in the "
                "modeller)", path.c_str(), static_cast<unsigned long long>(fanned_concave_),
                PolygonSplitter::kMaxClippedCorners);
  return OkStatus();
}

}  // namespace raystack::import
