#pragma once
// The converter's input side: triangles from readers or generators are packed into a
// TriangleSpool (ids in source order; materials renumbered into one table of those the faces
// use, in order of first use: an MTL's other definitions are never stored), and the spool is
// offered to the octree builder as a TriangleSource, optionally replicated on a grid the way
// the thesis built its huge models (Chevrolet x4096) — without writing the copies out first.

#include <array>
#include <cstdint>
#include <vector>

#include "common/base/status.h"
#include "tools/import/model_reader.h"
#include "tools/prep/octree_builder.h"
#include "tools/prep/triangle_spool.h"

namespace raystack::prep {

// Packs triangles into a spool. One sink takes several inputs in turn.
class SpoolSink : public import::TriangleSink {
 public:
  explicit SpoolSink(TriangleSpool* spool) : spool_(spool) {}

  // Material indices of the next input are shifted by `offset` (its place in the merged table
  // of every input's materials).
  void set_material_offset(uint32_t offset) { material_offset_ = offset; }
  Status Consume(std::span<const import::SourceTriangle> batch) override;
  // The merged table's indices of the materials faces use, in the store's order (a store
  // material k is the merged table's used_materials()[k]).
  const std::vector<uint32_t>& used_materials() const { return used_; }

  const Bounds3f& bounds() const { return bounds_; }
  bool has_attributes() const { return normals_ || uvs_; }
  bool has_normals() const { return normals_; }
  bool has_uvs() const { return uvs_; }
  uint64_t triangles() const { return next_id_; }

 private:
  TriangleSpool* spool_;
  uint32_t material_offset_ = 0;
  std::vector<uint32_t> store_id_;  // merged index -> store material, kNoMaterial until used
  std::vector<uint32_t> used_;
  uint64_t next_id_ = 0;
  Bounds3f bounds_;
  bool normals_ = false, uvs_ = false;
};

// The spooled model, repeated on an nx x ny x nz grid (1,1,1 = as is). Copy c of triangle i
// gets id c * triangles + i; copies are spaced by the model's extent plus 10%.
class ReplicatedSource : public TriangleSource {
 public:
  ReplicatedSource(const TriangleSpool& spool, const Bounds3f& bounds, bool attributes,
                   std::array<int, 3> grid);

  Status ForEach(const TriangleSpool::Visitor& visit) const override;
  // Pieces are runs of copies, or runs of the model's triangles when there is one copy (and
  // the spool's records all have the same size).
  int MaxParts() const override;
  Status ForEachPart(int part, int parts, const TriangleSpool::Visitor& visit) const override;
  uint64_t triangles() const override { return spool_.triangles() * copies(); }
  uint64_t bytes() const override { return spool_.bytes() * copies(); }
  Bounds3f bounds() const override { return bounds_; }
  bool has_attributes() const override { return attributes_; }
  uint64_t copies() const { return uint64_t(grid_[0]) * grid_[1] * grid_[2]; }

 private:
  // Copies [first, end) in order, each moved to its place on the grid.
  Status ForEachCopy(uint64_t first, uint64_t end, const TriangleSpool::Visitor& visit) const;

  const TriangleSpool& spool_;
  Bounds3f base_, bounds_;
  bool attributes_;
  std::array<int, 3> grid_;
  Vec3f step_;
};

}  // namespace raystack::prep
