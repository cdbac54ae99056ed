#include "tools/import/obj_reader.h"

#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <set>
#include <string>
#include <vector>

#include "common/base/log.h"
#include "tools/import/mtl_reader.h"
#include "tools/import/text_scan.h"
#include "tools/import/triangle_batcher.h"
#include "tools/import/vertex_table.h"

namespace raystack::import {
namespace {

// MTL files are small; a small buffer is plenty.
constexpr size_t kMtlBufferBytes = size_t{64} << 10;

// An OBJ says nothing of its size up front; its bytes give the fewest triangles it may hold
// at this many bytes each, its share of the `v`, `vt` and `vn` lines included (the shared
// models: 32 for the motorBike, 82 for the conference room, 80 for the Cornell box's quads;
// triangles that share no corner, each with its own full-precision v, vt and vn: about 400).
constexpr uint64_t kObjMostBytesPerTriangle = 512;

// Keywords are identifiers; anything else means the file is not OBJ text (or is damaged).
bool IsKeyword(std::string_view word) {
  auto is_alpha = [](char c) { return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_'; };
  if (word.empty() || !is_alpha(word.front())) return false;
  for (char c : word)
    if (!is_alpha(c) && !(c >= '0' && c <= '9')) return false;
  return true;
}

class ObjReader {
 public:
  ObjReader(BufferedInput& input, const ReadOptions& options, TriangleSink& sink,
            ModelInfo* info)
      : input_(input), info_(info), shift_(options.shift), budget_(options.vertex_memory_bytes),
        positions_(3, &budget_, options.temp_dir), uvs_(2, &budget_, options.temp_dir),
        normals_(3, &budget_, options.temp_dir),
        batcher_(sink, info, options.max_triangles) {}

  Status Read();

 private:
  // Returns the next logical line (continuation lines joined); false at the end.
  bool NextStatement(std::string_view* line);
  Status ReadStatement(std::string_view line);
  Status ReadFloats(std::string_view* rest, float* out, int required, int optional,
                    bool* finite = nullptr);
  Status ReadPosition(std::string_view rest);
  Status ReadTexCoord(std::string_view rest);
  Status ReadNormal(std::string_view rest);
  Status ReadFace(std::string_view rest);
  Status ReadCorner(std::string_view token, FaceCorner* corner);
  Status ResolveIndex(std::string_view text, const VertexTable& table, const char* what,
                      uint64_t* index);
  Status EmitFace();
  Status LoadMaterialLibraries(std::string_view rest);
  void WarnOnce(std::string_view keyword);
  Status Finish();

  BufferedInput& input_;
  ModelInfo* info_;
  PositionShift* shift_;  // --shift, or null
  MemoryBudget budget_;
  VertexTable positions_;
  VertexTable uvs_;
  VertexTable normals_;
  TriangleBatcher batcher_;
  MaterialTable materials_;
  uint32_t material_ = kNoMaterial;
  std::vector<FaceCorner> corners_;  // of the current face; reused
  std::string joined_;           // a statement continued over several lines
  std::set<std::string, std::less<>> warned_keywords_;
  bool colours_noted_ = false;
  std::set<std::string, std::less<>> libraries_;  // loaded already (concatenated OBJs repeat them)
};

Status ObjReader::Read() {
  std::string_view line;
  while (NextStatement(&line)) RAYSTACK_RETURN_IF_ERROR(ReadStatement(line));
  RAYSTACK_RETURN_IF_ERROR(input_.status());
  return Finish();
}

bool ObjReader::NextStatement(std::string_view* line) {
  // A backslash in a comment continues nothing ("# Exported from D:\\Projects\\" swallowed the
  // vertex after it).
  auto continues = [](std::string_view text) {
    text = Trim(StripComment(text));
    return !text.empty() && text.back() == '\\';
  };
  if (!input_.NextLine(line)) return false;
  if (!continues(*line)) return true;
  joined_.clear();
  std::string_view part = *line;
  do {
    part = Trim(StripComment(part));
    joined_.append(part.substr(0, part.size() - 1));
    joined_.push_back(' ');
  } while (input_.NextLine(&part) && continues(part));
  if (!continues(part)) joined_.append(part);  // the last line of the statement
  *line = joined_;
  return input_.status().ok();
}

Status ObjReader::ReadStatement(std::string_view line) {
  if (input_.line_number() == 1) line = WithoutByteOrderMark(line);
  std::string_view rest = StripComment(line);
  std::string_view keyword = NextToken(&rest);
  if (keyword.empty()) return OkStatus();
  if (keyword == "f") return ReadFace(rest);
  if (keyword == "v" || keyword == "vt" || keyword == "vn") {
    // "-1.#IND" is a number that is not finite, not "-1." and a comment (a position written
    // so must be an error, not -1).
    rest = StripCommentKeepingMsvcNonFinite(line);
    NextToken(&rest);  // the keyword
    return keyword == "v" ? ReadPosition(rest) : keyword == "vt" ? ReadTexCoord(rest) : ReadNormal(rest);
  }
  if (keyword == "usemtl") {
    std::string_view name = Trim(rest);
    material_ = name.empty() ? kNoMaterial : materials_.Use(name);
    return OkStatus();
  }
  if (keyword == "mtllib") return LoadMaterialLibraries(rest);
  if (keyword == "o" || keyword == "g" || keyword == "s") return OkStatus();
  if (!IsKeyword(keyword))
    return input_.LineError("not an OBJ statement (is this an OBJ text file?)");
  WarnOnce(keyword);
  return OkStatus();
}

// `required` numbers, then up to `optional` more. With `finite` given (texture coordinates and
// normals, optional data), a number that is not finite is kept as NaN and *finite cleared, so
// the faces that use it go without (a warning counts them) rather than the whole model being
// refused for it; positions (`finite` null) must be finite.
Status ObjReader::ReadFloats(std::string_view* rest, float* out, int required, int optional,
                             bool* finite) {
  for (int i = 0; i < required + optional; ++i) {
    std::string_view token = NextToken(rest);
    if (token.empty()) {
      if (i < required)
        return input_.LineError(StrFormat("expected %d numbers, found %d", required, i));
      break;
    }
    if (const char* why = ParseFloat(token, &out[i])) {
      if (!finite || (!SpellsNonFinite(token) && std::strcmp(why, "number out of float range") != 0))
        return input_.LineError(std::string(why) + ": " + Quoted(token));
      out[i] = std::numeric_limits<float>::quiet_NaN();
      *finite = false;
    }
  }
  return OkStatus();
}

Status ObjReader::ReadPosition(std::string_view rest) {
  float xyz[3];
  if (shift_) {  // in double, shifted, then float
    double wide[3];
    for (int a = 0; a < 3; ++a) {
      const std::string_view token = NextToken(&rest);
      if (token.empty())
        return input_.LineError(StrFormat("expected 3 numbers, found %d", a));
      if (const char* why = ParseDouble(token, &wide[a]))
        return input_.LineError(std::string(why) + ": " + Quoted(token));
    }
    shift_->Apply(wide, xyz);
  } else {
    RAYSTACK_RETURN_IF_ERROR(ReadFloats(&rest, xyz, 3, 0));  // w or vertex colours may follow
  }
  if (const char* why = PositionOutOfRange(xyz)) return input_.LineError(why);
  if (!colours_noted_) {  // "v x y z r g b" (MeshLab, scanners): the model would come out grey
    std::string_view after = rest;
    int more = 0;
    while (!NextToken(&after).empty()) ++more;
    if (more >= 3) {
      colours_noted_ = true;
      LOG_WARNING("import", "%s:%llu: vertex colours ('v x y z r g b') are not read: surfaces "
                  "take their material's colour (a scene can set it)", input_.path().c_str(),
                  static_cast<unsigned long long>(input_.line_number()));
    }
  }
  info_->bounds.Extend(Vec3f{xyz[0], xyz[1], xyz[2]});
  ++info_->vertices;
  return positions_.Append(xyz);
}

Status ObjReader::ReadTexCoord(std::string_view rest) {
  float uv[2] = {0, 0};
  bool finite = true;
  RAYSTACK_RETURN_IF_ERROR(ReadFloats(&rest, uv, 1, 1, &finite));  // a third (w) may follow
  if (!finite) ++info_->attributes_not_finite;
  return uvs_.Append(uv);
}

Status ObjReader::ReadNormal(std::string_view rest) {
  float n[3];
  bool finite = true;
  RAYSTACK_RETURN_IF_ERROR(ReadFloats(&rest, n, 3, 0, &finite));
  if (!finite) ++info_->attributes_not_finite;
  return normals_.Append(n);
}

Status ObjReader::ReadFace(std::string_view rest) {
  corners_.clear();
  for (std::string_view token = NextToken(&rest); !token.empty(); token = NextToken(&rest)) {
    corners_.emplace_back();
    RAYSTACK_RETURN_IF_ERROR(ReadCorner(token, &corners_.back()));
  }
  if (corners_.size() < 3) {  // an edge or a point: no surface
    ++info_->faces_under_three_corners;
    return OkStatus();
  }
  ++info_->faces;
  return EmitFace();
}

// "v", "v/vt", "v//vn" or "v/vt/vn".
Status ObjReader::ReadCorner(std::string_view token, FaceCorner* corner) {
  const std::string_view whole = token;
  std::string_view parts[3];
  int count = 0;
  for (;;) {
    if (count == 3) return input_.LineError("face vertex '" + std::string(whole) +
                                            "' has more than 3 indices");
    size_t slash = token.find('/');
    parts[count++] = token.substr(0, slash);
    if (slash == std::string_view::npos) break;
    token.remove_prefix(slash + 1);
  }
  uint64_t index = 0;
  float values[3];
  RAYSTACK_RETURN_IF_ERROR(ResolveIndex(parts[0], positions_, "face index", &index));
  RAYSTACK_RETURN_IF_ERROR(positions_.Get(index, values));
  corner->p = {values[0], values[1], values[2]};
  if (!parts[1].empty()) {
    RAYSTACK_RETURN_IF_ERROR(ResolveIndex(parts[1], uvs_, "texture index", &index));
    RAYSTACK_RETURN_IF_ERROR(uvs_.Get(index, corner->uv));
    corner->has_uv = std::isfinite(corner->uv[0]) && std::isfinite(corner->uv[1]);
  }
  if (!parts[2].empty()) {
    RAYSTACK_RETURN_IF_ERROR(ResolveIndex(parts[2], normals_, "normal index", &index));
    RAYSTACK_RETURN_IF_ERROR(normals_.Get(index, values));
    corner->n = {values[0], values[1], values[2]};
    corner->has_normal =
        std::isfinite(values[0]) && std::isfinite(values[1]) && std::isfinite(values[2]);
  }
  return OkStatus();
}

// OBJ counts from 1; negative indices count back from the last element read so far.
Status ObjReader::ResolveIndex(std::string_view text, const VertexTable& table, const char* what,
                               uint64_t* index) {
  int64_t raw = 0;
  if (const char* why = ParseInt(text, &raw))
    return input_.LineError(StrFormat("%s '%.*s': %s", what, static_cast<int>(text.size()),
                                      text.data(), why));
  const auto count = static_cast<int64_t>(table.size());
  if (raw > 0 && raw <= count) {
    *index = static_cast<uint64_t>(raw - 1);
    return OkStatus();
  }
  if (raw < 0 && raw >= -count) {
    *index = static_cast<uint64_t>(count + raw);
    return OkStatus();
  }
  if (raw == 0) return input_.LineError(StrFormat("%s 0 is invalid (OBJ counts from 1)", what));
  return input_.LineError(StrFormat("%s %lld out of range (file has %lld %s so far)", what,
                                    static_cast<long long>(raw), static_cast<long long>(count),
                                    &table == &positions_ ? "vertices"
                                    : &table == &uvs_     ? "texture coordinates"
                                                          : "normals"));
}

Status ObjReader::EmitFace() {
  if (batcher_.WouldExceedLimit(corners_.size() - 2))
    return input_.LineError(StrFormat("more than %llu triangles",
                                      static_cast<unsigned long long>(batcher_.max_triangles())));
  return batcher_.AddPolygon(corners_, material_);
}

// `mtllib a.mtl b.mtl`: paths relative to the OBJ's folder. A missing library is a warning:
// the geometry is still worth having, with default materials. A malformed one is an error.
// Blender writes a file name with spaces as it is (`mtllib my model.mtl`): the whole rest of
// the line is tried first as one name, as Blender's own importer does.
Status ObjReader::LoadMaterialLibraries(std::string_view rest) {
  std::filesystem::path folder = std::filesystem::path(input_.path()).parent_path();
  const std::string_view whole = Trim(rest);
  std::error_code ec;
  const bool one_name = whole.find_first_of(" \t") != std::string_view::npos &&
                        std::filesystem::is_regular_file(folder / std::string(whole), ec);
  for (std::string_view name = one_name ? whole : NextToken(&rest); !name.empty();
       name = one_name ? std::string_view() : NextToken(&rest)) {
    std::string path = (folder / std::string(name)).string();
    if (!libraries_.insert(path).second) continue;
    Expected<BufferedInput> mtl = BufferedInput::Open(path, nullptr, kMtlBufferBytes);
    if (!mtl.ok()) {
      LOG_WARNING("import", "%s:%llu: material library not loaded: %s", input_.path().c_str(),
                  static_cast<unsigned long long>(input_.line_number()),
                  mtl.status().message().c_str());
      continue;
    }
    RAYSTACK_RETURN_IF_ERROR(ReadMtl(*mtl, &materials_));
  }
  return OkStatus();
}

void ObjReader::WarnOnce(std::string_view keyword) {
  if (!warned_keywords_.insert(std::string(keyword)).second) return;
  LOG_WARNING("import", "%s:%llu: %s statements are not supported; skipping them",
              input_.path().c_str(), static_cast<unsigned long long>(input_.line_number()),
              Quoted(keyword).c_str());
}

Status ObjReader::Finish() {
  RAYSTACK_RETURN_IF_ERROR(batcher_.Finish(input_.path()));
  // A model may use thousands of names its missing MTL defined: a few, then a count.
  constexpr size_t kNamed = 8;
  const std::vector<std::string> undefined = materials_.UndefinedNames();
  for (size_t i = 0; i < undefined.size() && i < kNamed; ++i)
    LOG_WARNING("import", "%s: material '%s' is defined in no MTL file: it renders as the "
                "converter's default (diffuse, Kd 0.8), and a scene can set it by name "
                "(\"materials\": {\"%s\": ...})", input_.path().c_str(), undefined[i].c_str(),
                undefined[i].c_str());
  if (undefined.size() > kNamed)
    LOG_WARNING("import", "%s: %zu more materials are defined in no MTL file",
                input_.path().c_str(), undefined.size() - kNamed);
  info_->materials = materials_.Take();
  return OkStatus();
}

}  // namespace

Status ReadObj(BufferedInput& input, const ReadOptions& options, TriangleSink& sink,
               ModelInfo* info) {
  // What the converter checks its disk against before hours of reading, as a PLY header's
  // count: the fewest triangles the file may hold, so it warns only of a disk surely too small.
  if (options.declared && input.file_size() >= kObjMostBytesPerTriangle)
    options.declared({input.file_size() / kObjMostBytesPerTriangle, 0, false, /*lower_bound=*/true});
  ObjReader reader(input, options, sink, info);
  return reader.Read();
}

}  // namespace raystack::import
