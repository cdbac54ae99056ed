#pragma once
// An append-only sequence of triangles (PackedTriangle, followed by TriangleAttributes when the
// triangle has any) that stays in memory up to a budget and spills to a file beyond it. The
// converter keeps the parsed model and each partition bucket in one, so its memory is bounded
// whatever the model's size.

#include <cstdint>
#include <cstdio>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/store/block_encoder.h"

namespace raystack::prep {

using store::PackedTriangle;
using store::TriangleAttributes;

class WriteBehind;

class TriangleSpool {
 public:
  // `path` is where it spills (created on first spill); `memory_budget` bytes stay in RAM;
  // `file_buffer` bytes buffer writes once spilled (small when hundreds are open at once).
  TriangleSpool(std::string path, uint64_t memory_budget, size_t file_buffer = 1 << 20);
  // Spills at once, through `writer` (which must outlive the spool until Close): its buffers
  // are filled here and written on its thread.
  TriangleSpool(std::string path, WriteBehind& writer);
  ~TriangleSpool();
  TriangleSpool(TriangleSpool&&) noexcept;
  TriangleSpool& operator=(TriangleSpool&&) = delete;

  // `attributes` must be non-null when `t` has normals or uvs.
  Status Append(const PackedTriangle& t, const TriangleAttributes* attributes);
  // Finishes writing; the spool becomes readable. Idempotent.
  Status Close();

  uint64_t triangles() const { return triangles_; }
  uint64_t bytes() const { return bytes_; }
  bool spilled() const { return file_ != nullptr || spilled_; }

  // Streams every triangle, in order, in batches. `visit(tris, attrs)`: attrs is parallel to
  // tris when any triangle of the spool has attributes (entries of triangles without are
  // unspecified), and empty otherwise. An error stops the scan.
  using Visitor = std::function<Status(std::span<const PackedTriangle>,
                                       std::span<const TriangleAttributes>)>;
  Status ForEach(const Visitor& visit) const;
  // Streams triangles [first, first + count) of a spool whose records all have the same size
  // (no triangle with attributes): the converter reads pieces of one spool on several threads.
  Status ForEachRange(uint64_t first, uint64_t count, const Visitor& visit) const;
  bool has_attributes() const { return has_attributes_; }
  // Deletes the spill file and frees memory.
  void Clear();

 private:
  Status Spill();
  // Every record a bare PackedTriangle: triangles [first, first + count).
  Status ForEachPlain(uint64_t first, uint64_t count, const Visitor& visit) const;
  Status AppendBehind(const PackedTriangle& t, const TriangleAttributes* attributes, bool with);

  std::string path_;
  uint64_t memory_budget_;
  size_t file_buffer_;
  std::vector<uint8_t> memory_;
  std::FILE* file_ = nullptr;
  WriteBehind* writer_ = nullptr;  // when set, writes go through it to fd_
  int fd_ = -1;
  std::vector<uint8_t> pending_;  // the writer's buffer being filled
  bool spilled_ = false;
  uint64_t triangles_ = 0, bytes_ = 0;
  bool has_attributes_ = false;
};

}  // namespace raystack::prep
