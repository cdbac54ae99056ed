#include "tools/prep/model_source.h"

#include <algorithm>

#include "common/base/log.h"

namespace raystack::prep {

Status SpoolSink::Consume(std::span<const import::SourceTriangle> batch) {
  for (const import::SourceTriangle& s : batch) {
    if (next_id_ >= store::kMaxTriangles)
      return Status::Error("more than 4,294,967,294 triangles: a store's triangle ids are 32-bit");
    PackedTriangle t;
    TriangleAttributes a{};
    for (int c = 0; c < 3; ++c) {
      t.p[c] = s.p[c];
      bounds_.Extend(s.p[c]);
      if (s.has_normals) a.n[c] = s.n[c];
      if (s.has_uvs) {
        a.uv[c][0] = s.uv[c][0];
        a.uv[c][1] = s.uv[c][1];
      }
    }
    t.id = static_cast<uint32_t>(next_id_++);
    uint32_t material = store::kNoMaterial;
    if (s.material != import::kNoMaterial) {
      const uint64_t merged = uint64_t{s.material} + material_offset_;
      if (merged >= store_id_.size()) store_id_.resize(merged + 1, store::kNoMaterial);
      material = store_id_[merged];
      if (material == store::kNoMaterial) {
        if (used_.size() >= store::kMaxMaterials)
          // (Undefined names count too: a hostile-input review's 70,000 were blamed on the MTLs.)
          return Status::Error("more than 65534 materials used by the faces (the store format's "
                               "limit): each 'usemtl' name that no MTL defines counts as one");
        material = store_id_[merged] = static_cast<uint32_t>(used_.size());
        used_.push_back(static_cast<uint32_t>(merged));
      }
    }
    t.material_and_flags = material | (s.has_normals ? PackedTriangle::kHasNormals : 0) |
                           (s.has_uvs ? PackedTriangle::kHasUvs : 0);
    normals_ |= s.has_normals;
    uvs_ |= s.has_uvs;
    RAYSTACK_RETURN_IF_ERROR(spool_->Append(t, &a));
  }
  return OkStatus();
}

ReplicatedSource::ReplicatedSource(const TriangleSpool& spool, const Bounds3f& bounds,
                                   bool attributes, std::array<int, 3> grid)
    : spool_(spool), base_(bounds), bounds_(bounds), attributes_(attributes), grid_(grid) {
  const Vec3f e = bounds.Empty() ? Vec3f{0, 0, 0} : bounds.Extent();
  step_ = e * 1.1f;
  if (!bounds.Empty())
    bounds_.upper = bounds.upper + Vec3f{step_.x * static_cast<float>(grid[0] - 1),
                                         step_.y * static_cast<float>(grid[1] - 1),
                                         step_.z * static_cast<float>(grid[2] - 1)};
}

Status ReplicatedSource::ForEach(const TriangleSpool::Visitor& visit) const {
  if (copies() == 1) return spool_.ForEach(visit);
  return ForEachCopy(0, copies(), visit);
}

int ReplicatedSource::MaxParts() const {
  constexpr uint64_t kMinPiece = 1 << 16;  // triangles: smaller pieces are not worth a thread
  if (copies() > 1) return static_cast<int>(std::min<uint64_t>(copies(), 64));
  if (spool_.has_attributes()) return 1;
  return static_cast<int>(std::clamp<uint64_t>(spool_.triangles() / kMinPiece, 1, 64));
}

Status ReplicatedSource::ForEachPart(int part, int parts, const TriangleSpool::Visitor& visit) const {
  if (parts < 1 || parts > MaxParts() || part < 0 || part >= parts)
    return Status::Error(StrFormat("piece %d of %d: the model offers at most %d", part, parts,
                                   MaxParts()));
  const auto piece = [&](uint64_t total, uint64_t* first, uint64_t* end) {
    *first = total * static_cast<uint64_t>(part) / static_cast<uint64_t>(parts);
    *end = total * static_cast<uint64_t>(part + 1) / static_cast<uint64_t>(parts);
  };
  // One piece is the whole model, read in order whatever its records' sizes.
  if (parts == 1) return ForEach(visit);
  uint64_t first, end;
  if (copies() > 1) {
    piece(copies(), &first, &end);
    return ForEachCopy(first, end, visit);
  }
  piece(spool_.triangles(), &first, &end);
  return spool_.ForEachRange(first, end - first, visit);
}

Status ReplicatedSource::ForEachCopy(uint64_t first, uint64_t end,
                                     const TriangleSpool::Visitor& visit) const {
  const uint64_t n = spool_.triangles();
  const auto nx = static_cast<uint64_t>(grid_[0]), ny = static_cast<uint64_t>(grid_[1]);
  std::vector<PackedTriangle> moved;
  for (uint64_t copy = first; copy < end; ++copy) {
    // Copies run x fastest, then y, then z.
    const uint64_t x = copy % nx, y = copy / nx % ny, z = copy / (nx * ny);
    const Vec3f offset{step_.x * static_cast<float>(x), step_.y * static_cast<float>(y),
                       step_.z * static_cast<float>(z)};
    RAYSTACK_RETURN_IF_ERROR(spool_.ForEach(
        [&](std::span<const PackedTriangle> tris, std::span<const TriangleAttributes> attrs) {
          moved.assign(tris.begin(), tris.end());
          for (PackedTriangle& t : moved) {
            for (Vec3f& p : t.p) p = p + offset;
            t.id = static_cast<uint32_t>(copy * n + t.id);
          }
          return visit(moved, attrs);
        }));
  }
  return OkStatus();
}

}  // namespace raystack::prep
