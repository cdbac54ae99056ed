#include "tools/import/ply_reader.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "common/base/log.h"
#include "tools/import/ply_header.h"
#include "tools/import/ply_values.h"
#include "tools/import/text_scan.h"
#include "tools/import/triangle_batcher.h"
#include "tools/import/vertex_table.h"

namespace raystack::import {
namespace {

// Larger polygons do not occur in scanned or modelled meshes; a larger count is damage, and
// the cap keeps the corner buffer small.
constexpr int64_t kMaxFaceVertices = 1024;

// Where each vertex property lands in a vertex-table record (-1: read and dropped).
struct VertexLayout {
  std::vector<int> slot_of_property;
  int floats = 3;  // x y z [nx ny nz] [u v]
  bool has_normals = false;
  bool has_uvs = false;
};

class PlyReader {
 public:
  PlyReader(BufferedInput& input, const ReadOptions& options, TriangleSink& sink,
            ModelInfo* info)
      : input_(input), options_(options), info_(info), budget_(options.vertex_memory_bytes),
        batcher_(sink, info, options.max_triangles) {}

  Status Read();

 private:
  Status MakeVertexLayout(const PlyElement& element, VertexLayout* layout) const;
  void WarnAboutTrailingData(PlyFormat format);
  Status ReadVertices(const PlyElement& element);
  void WarnOfColours(const PlyElement& element) const;
  void WarnOfTooManyFaces(const PlyHeader& header) const;
  template <typename ReadList, typename AfterRecord>
  Status ReadIndexLists(const PlyElement& element, ReadList&& read_list, AfterRecord&& after_record);
  Status ReadFaces(const PlyElement& element);
  Status ReadFaceCorners(const PlyProperty& list);
  Status ReadTriangleStrips(const PlyElement& element);
  Status ReadStrip(const PlyProperty& list);
  Status Corner(int64_t index, FaceCorner* corner);
  Status SkipElement(const PlyElement& element);
  Status SkipProperty(const PlyProperty& property);

  BufferedInput& input_;
  const ReadOptions& options_;
  ModelInfo* info_;
  MemoryBudget budget_;
  TriangleBatcher batcher_;
  std::unique_ptr<PlyValueReader> values_;
  std::unique_ptr<VertexTable> vertices_;  // created by the vertex element
  VertexLayout layout_;
  std::vector<FaceCorner> corners_;  // of the current face; reused
};

Status PlyReader::Read() {
  Expected<PlyHeader> header = ReadPlyHeader(input_);
  if (!header.ok()) return header.status();
  values_ = std::make_unique<PlyValueReader>(input_, header->format);
  WarnOfTooManyFaces(*header);
  if (options_.declared) {
    DeclaredModel declared;
    for (const PlyElement& element : header->elements) {
      if (element.name == "face") declared.faces = element.count;
      if (element.name != "vertex") continue;
      declared.vertices = element.count;
      for (const char* attribute : {"nx", "u", "s", "texture_u", "texture_s"})
        declared.attributes = declared.attributes || element.Find(attribute) >= 0;
    }
    if (declared.faces > 0) options_.declared(declared);
  }
  for (const PlyElement& element : header->elements) {
    if (element.name == "vertex") {
      RAYSTACK_RETURN_IF_ERROR(ReadVertices(element));
    } else if (element.name == "face" || element.name == "tristrips") {
      if (!vertices_)
        return input_.LineError("PLY " + element.name +
                                " element before the vertex element is not supported");
      RAYSTACK_RETURN_IF_ERROR(element.name == "face" ? ReadFaces(element)
                                                      : ReadTriangleStrips(element));
    } else {
      // Other elements (edges, materials, ...) hold no triangles; one with a vertex index list
      // might, so its leaving out is said.
      if (element.Find("vertex_indices") >= 0 || element.Find("vertex_index") >= 0)
        LOG_WARNING("import", "%s: element '%s' (%llu) ignored: only 'face' and 'tristrips' "
                    "give triangles", input_.path().c_str(), element.name.c_str(),
                    static_cast<unsigned long long>(element.count));
      RAYSTACK_RETURN_IF_ERROR(SkipElement(element));
    }
  }
  if (!vertices_) return input_.LineError("PLY file has no vertex element");
  WarnAboutTrailingData(header->format);
  return batcher_.Finish(input_.path());
}

// Data past the elements the header declares is ignored, with a warning: a header whose counts
// are too small would otherwise drop part of the model without a word.
void PlyReader::WarnAboutTrailingData(PlyFormat format) {
  if (format == PlyFormat::kAscii) {
    std::string_view line;
    while (input_.NextLine(&line)) {
      if (Trim(line).empty()) continue;
      LOG_WARNING("import", "%s:%llu: data after the elements the header declares; ignored",
                  input_.path().c_str(), static_cast<unsigned long long>(input_.line_number()));
      return;
    }
  } else if (!input_.Peek(1).empty()) {
    LOG_WARNING("import", "%s: byte %llu: %llu bytes after the elements the header declares; "
                "ignored", input_.path().c_str(), static_cast<unsigned long long>(input_.offset()),
                static_cast<unsigned long long>(input_.file_size() - input_.offset()));
  }
}

Status PlyReader::MakeVertexLayout(const PlyElement& element, VertexLayout* layout) const {
  auto find_scalar = [&](std::initializer_list<const char*> names) {
    for (const char* name : names) {
      int index = element.Find(name);
      if (index >= 0 && !element.properties[static_cast<size_t>(index)].is_list) return index;
    }
    return -1;
  };
  int x = find_scalar({"x"}), y = find_scalar({"y"}), z = find_scalar({"z"});
  if (x < 0 || y < 0 || z < 0)
    return input_.LineError("PLY vertex element lacks scalar x, y and z properties");
  int nx = find_scalar({"nx"}), ny = find_scalar({"ny"}), nz = find_scalar({"nz"});
  int u = find_scalar({"u", "s", "texture_u", "texture_s"});
  int v = find_scalar({"v", "t", "texture_v", "texture_t"});
  layout->slot_of_property.assign(element.properties.size(), -1);
  auto place = [&](int property) {
    layout->slot_of_property[static_cast<size_t>(property)] = layout->floats++;
  };
  layout->floats = 0;
  place(x), place(y), place(z);
  layout->has_normals = nx >= 0 && ny >= 0 && nz >= 0;
  if (layout->has_normals) place(nx), place(ny), place(nz);
  layout->has_uvs = u >= 0 && v >= 0;
  if (layout->has_uvs) place(u), place(v);
  WarnOfColours(element);
  return OkStatus();
}

Status PlyReader::ReadVertices(const PlyElement& element) {
  RAYSTACK_RETURN_IF_ERROR(MakeVertexLayout(element, &layout_));
  vertices_ = std::make_unique<VertexTable>(layout_.floats, &budget_, options_.temp_dir);
  float record[VertexTable::kMaxFloatsPerVertex];
  double position[3];  // --shift: x, y, z in double, shifted into record[0 .. 3)
  // `element.count` comes from the file: it bounds the loop, never an allocation.
  for (uint64_t i = 0; i < element.count; ++i) {
    RAYSTACK_RETURN_IF_ERROR(values_->BeginRecord(element.name));
    for (size_t p = 0; p < element.properties.size(); ++p) {
      const PlyProperty& property = element.properties[p];
      int slot = layout_.slot_of_property[p];
      if (slot < 0) {
        RAYSTACK_RETURN_IF_ERROR(SkipProperty(property));
        continue;
      }
      // Normals and texture coordinates (slots past x, y, z) are optional data: one that is
      // not a finite number reads as NaN and its faces go without it (a warning counts them).
      Status read = options_.shift && slot < 3
                        ? values_->ReadDouble(property.type, &position[slot])
                        : values_->ReadFloat(property.type, &record[slot], slot >= 3);
      if (!read.ok())
        return Status::Error(read.message() + StrFormat(" (vertex %llu, property '%s')",
                                                        static_cast<unsigned long long>(i),
                                                        property.name.c_str()));
    }
    if (options_.shift) options_.shift->Apply(position, record);
    for (int slot = 3; slot < layout_.floats; ++slot)
      if (!std::isfinite(record[slot])) {
        ++info_->attributes_not_finite;
        break;
      }
    if (const char* why = PositionOutOfRange(record)) return values_->Error(why);
    RAYSTACK_RETURN_IF_ERROR(values_->EndRecord());
    info_->bounds.Extend(Vec3f{record[0], record[1], record[2]});
    RAYSTACK_RETURN_IF_ERROR(vertices_->Append(record));
    ++info_->vertices;
  }
  return OkStatus();
}

// Each record of a face or strip element: its vertex index list read by `read_list`, its
// other properties skipped, then `after_record` (once the record is complete).
template <typename ReadList, typename AfterRecord>
Status PlyReader::ReadIndexLists(const PlyElement& element, ReadList&& read_list,
                                 AfterRecord&& after_record) {
  int list = element.Find("vertex_indices");
  if (list < 0) list = element.Find("vertex_index");
  if (list < 0) return input_.LineError("PLY " + element.name + " element has no vertex_indices list");
  const PlyProperty& indices = element.properties[static_cast<size_t>(list)];
  if (!indices.is_list || !IsIntegerType(indices.type))
    return input_.LineError("PLY " + indices.name + " must be a list of integers");
  for (uint64_t i = 0; i < element.count; ++i) {
    RAYSTACK_RETURN_IF_ERROR(values_->BeginRecord(element.name));
    for (size_t p = 0; p < element.properties.size(); ++p) {
      if (p == static_cast<size_t>(list)) RAYSTACK_RETURN_IF_ERROR(read_list(indices));
      else RAYSTACK_RETURN_IF_ERROR(SkipProperty(element.properties[p]));
    }
    RAYSTACK_RETURN_IF_ERROR(values_->EndRecord());
    RAYSTACK_RETURN_IF_ERROR(after_record());
  }
  return OkStatus();
}

// Scanners and MeshLab colour vertices or faces ("red green blue"): the model would come out in
// its material's colour without a word.
// Said at the header, not after hours of reading: a face gives at least one triangle unless it
// has fewer than three corners, so faces past what this file may still add (the limit less what
// earlier files gave: ReadOptions::max_triangles) will almost surely end in the limit's error.
void PlyReader::WarnOfTooManyFaces(const PlyHeader& header) const {
  uint64_t faces = 0;  // (a header declares one face element at most)
  for (const PlyElement& element : header.elements)
    if (element.name == "face") faces = element.count;
  if (faces > batcher_.max_triangles())
    LOG_WARNING("import", "%s: the header declares %llu faces, more than the %llu triangles the "
                "store can still take (its triangle ids are 32-bit): unless most have fewer than "
                "3 corners, the conversion will stop with an error when it reaches the limit",
                input_.path().c_str(), static_cast<unsigned long long>(faces),
                static_cast<unsigned long long>(batcher_.max_triangles()));
}

void PlyReader::WarnOfColours(const PlyElement& element) const {
  for (const char* name : {"red", "diffuse_red", "r"})
    if (element.Find(name) >= 0) {
      LOG_WARNING("import", "%s: %s colours ('%s', ...) are not read: surfaces take their "
                  "material's colour (a scene can set it)", input_.path().c_str(),
                  element.name.c_str(), name);
      return;
    }
}

Status PlyReader::ReadFaces(const PlyElement& element) {
  WarnOfColours(element);
  return ReadIndexLists(
      element, [this](const PlyProperty& list) { return ReadFaceCorners(list); },
      [this] {
        if (corners_.size() < 3) {  // an edge or a point: no surface (its indices were checked)
          ++info_->faces_under_three_corners;
          return OkStatus();
        }
        ++info_->faces;
        if (batcher_.WouldExceedLimit(corners_.size() - 2))
          return values_->Error(StrFormat("more than %llu triangles",
                                          static_cast<unsigned long long>(batcher_.max_triangles())));
        return batcher_.AddPolygon(corners_, kNoMaterial);
      });
}

Status PlyReader::ReadFaceCorners(const PlyProperty& list) {
  int64_t count = 0;
  RAYSTACK_RETURN_IF_ERROR(values_->ReadInteger(list.count_type, &count));
  if (count < 0 || count > kMaxFaceVertices)
    return values_->Error(StrFormat("face with %lld vertices (0 to %lld supported)",
                                    static_cast<long long>(count),
                                    static_cast<long long>(kMaxFaceVertices)));
  corners_.resize(static_cast<size_t>(count));
  for (FaceCorner& corner : corners_) {
    int64_t index = 0;
    RAYSTACK_RETURN_IF_ERROR(values_->ReadInteger(list.type, &index));
    RAYSTACK_RETURN_IF_ERROR(Corner(index, &corner));
  }
  return OkStatus();
}

// The corner of vertex `index` (checked against the vertex count).
Status PlyReader::Corner(int64_t index, FaceCorner* corner) {
  if (index < 0 || static_cast<uint64_t>(index) >= vertices_->size())
    return values_->Error(StrFormat("face index %lld out of range (file has %llu vertices)",
                                    static_cast<long long>(index),
                                    static_cast<unsigned long long>(vertices_->size())));
  float record[VertexTable::kMaxFloatsPerVertex];
  RAYSTACK_RETURN_IF_ERROR(vertices_->Get(static_cast<uint64_t>(index), record));
  corner->p = {record[0], record[1], record[2]};
  int next = 3;
  corner->has_normal = layout_.has_normals;
  if (corner->has_normal) {
    corner->n = {record[next], record[next + 1], record[next + 2]};
    corner->has_normal = std::isfinite(record[next]) && std::isfinite(record[next + 1]) &&
                         std::isfinite(record[next + 2]);
    next += 3;
  }
  corner->has_uv = layout_.has_uvs;
  if (corner->has_uv) {
    corner->uv[0] = record[next], corner->uv[1] = record[next + 1];
    corner->has_uv = std::isfinite(corner->uv[0]) && std::isfinite(corner->uv[1]);
  }
  return OkStatus();
}

// A "tristrips" element (as Stanford's tools write it): each record a list of vertex indices,
// strips separated by -1; each index past a strip's second makes a triangle with the two
// before it, every other one turned over so that all face the same way.
Status PlyReader::ReadTriangleStrips(const PlyElement& element) {
  return ReadIndexLists(
      element, [this](const PlyProperty& list) { return ReadStrip(list); },
      [] { return OkStatus(); });
}

Status PlyReader::ReadStrip(const PlyProperty& list) {
  int64_t count = 0;
  RAYSTACK_RETURN_IF_ERROR(values_->ReadInteger(list.count_type, &count));
  if (count < 0) return values_->Error(StrFormat("strip with %lld indices", static_cast<long long>(count)));
  FaceCorner window[3];  // the last two corners of the strip, and the new one
  int64_t in_strip = 0;  // corners of the current strip so far
  for (int64_t k = 0; k < count; ++k) {
    int64_t index = 0;
    RAYSTACK_RETURN_IF_ERROR(values_->ReadInteger(list.type, &index));
    if (index == -1 || index == 0xffffffffll) {  // the next strip starts (-1, as uint too)
      in_strip = 0;
      continue;
    }
    RAYSTACK_RETURN_IF_ERROR(Corner(index, &window[2]));
    if (in_strip >= 2) {
      ++info_->faces;
      if (batcher_.WouldExceedLimit(1))
        return values_->Error(StrFormat("more than %llu triangles",
                                        static_cast<unsigned long long>(batcher_.max_triangles())));
      corners_.assign({window[in_strip % 2 == 0 ? 0 : 1], window[in_strip % 2 == 0 ? 1 : 0],
                       window[2]});
      RAYSTACK_RETURN_IF_ERROR(batcher_.AddPolygon(corners_, kNoMaterial));
    }
    window[0] = window[1];
    window[1] = window[2];
    ++in_strip;
  }
  return OkStatus();
}

Status PlyReader::SkipElement(const PlyElement& element) {
  for (uint64_t i = 0; i < element.count; ++i) {
    RAYSTACK_RETURN_IF_ERROR(values_->BeginRecord(element.name));
    for (const PlyProperty& property : element.properties)
      RAYSTACK_RETURN_IF_ERROR(SkipProperty(property));
    RAYSTACK_RETURN_IF_ERROR(values_->EndRecord());
  }
  return OkStatus();
}

Status PlyReader::SkipProperty(const PlyProperty& property) {
  return property.is_list ? values_->SkipList(property.count_type, property.type)
                          : values_->Skip(property.type);
}

}  // namespace

Status ReadPly(BufferedInput& input, const ReadOptions& options, TriangleSink& sink,
               ModelInfo* info) {
  PlyReader reader(input, options, sink, info);
  return reader.Read();
}

}  // namespace raystack::import
