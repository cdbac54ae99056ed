#pragma once
// Streaming readers for triangle models (OBJ + MTL, PLY ascii / binary LE / binary BE).
// A reader never holds the whole model: faces are resolved against a vertex table that stays
// in memory up to a budget and spills to a temporary file beyond it, and triangles leave in
// fixed-size batches through a TriangleSink. Bad input is a Status naming the file and the
// line (text) or byte offset (binary); nothing is thrown, nothing crashes.

#include <cmath>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/geometry/bounds.h"
#include "common/geometry/float_range.h"
#include "common/geometry/vec.h"

namespace raystack {
class ProgressReporter;
}

namespace raystack::import {

inline constexpr uint32_t kNoMaterial = 0xffffffffu;

// Vertex coordinates beyond +-1e18 are refused where they are read (common/geometry/
// float_range.h: such a model would render wrong); models too small across once read.
inline constexpr float kMaxCoordinate = raystack::kMaxCoordinate;
inline constexpr float kMinExtent = raystack::kMinModelExtent;
inline const char* PositionOutOfRange(const float xyz[3]) {
  for (int a = 0; a < 3; ++a)
    if (!(std::fabs(xyz[a]) <= kMaxCoordinate))
      return "vertex coordinate beyond +-1e18 (float ray tracing overflows there: scale the "
             "model down)";
  return nullptr;
}

// One material from an MTL file (only what a ray tracer needs).
struct Material {
  std::string name;
  Vec3f kd{0.8f, 0.8f, 0.8f};  // diffuse albedo
  Vec3f ks{0, 0, 0};           // specular
  Vec3f ke{0, 0, 0};           // emission
  float ni = 0.0f;             // index of refraction; 0 when the MTL gives none
  float d = 1.0f;              // opacity
  int illum = 2;
  // Where its `newmtl` is ("file.mtl:12"), for messages; empty when no MTL defined it.
  std::string defined_at;
};

struct SourceTriangle {
  Vec3f p[3];
  Vec3f n[3];       // valid when has_normals
  float uv[3][2];   // valid when has_uvs
  uint32_t material = kNoMaterial;  // index into ModelInfo::materials
  bool has_normals = false;
  bool has_uvs = false;
};

// Receives triangles in source order, in batches (one virtual call per batch, not per triangle).
class TriangleSink {
 public:
  virtual ~TriangleSink() = default;
  // Returning an error stops the reader, which returns that error.
  virtual Status Consume(std::span<const SourceTriangle> batch) = 0;
};

// raystack-prep --shift: a translation subtracted from every position in double precision,
// before the position becomes a float, so that a model far from the origin for its size (a
// georeferenced scan) keeps its detail. `automatic`: the shift is set from the first position
// read, rounded to whole units, and then kept for every later one (and every later file).
struct PositionShift {
  bool automatic = false;
  bool set = false;   // `by` is known (given, or taken from the first position)
  double by[3] = {0, 0, 0};

  // The shifted position as floats; a position shifted past the float range is still caught
  // by PositionOutOfRange.
  void Apply(const double in[3], float out[3]) {
    if (automatic && !set) {
      for (int a = 0; a < 3; ++a) by[a] = std::round(in[a]);
      set = true;
    }
    for (int a = 0; a < 3; ++a) out[a] = static_cast<float>(in[a] - by[a]);
  }
};

// What a model file's header says of it, before its body is read.
struct DeclaredModel {
  uint64_t faces = 0, vertices = 0;
  bool attributes = false;  // normals or texture coordinates per vertex
  bool lower_bound = false;  // `faces` is the fewest the file may hold (an OBJ's size)
};

struct ReadOptions {
  uint64_t vertex_memory_bytes = 256ull << 20;  // vertex table budget before spilling to disk
  std::string temp_dir;                         // where the spill file goes ("" = $TMPDIR or /tmp)
  ProgressReporter* progress = nullptr;         // fed with input bytes consumed, if set
  // More is an error: a store's triangle ids are 32-bit (store::kMaxTriangles, which the
  // importer, a library of its own, does not include).
  uint64_t max_triangles = 0xfffffffeull;
  PositionShift* shift = nullptr;               // --shift (shared by a run's files), if any
  // Called with what a file's header declares (PLY), or for an OBJ the fewest faces its size
  // allows, before its body is read: the converter checks its disk against it (hours of
  // reading a large scan ended on a full disk).
  std::function<void(const DeclaredModel&)> declared;
};

struct ModelInfo {
  std::vector<Material> materials;  // referenced by SourceTriangle::material
  uint64_t vertices = 0;            // OBJ `v` lines or PLY vertex count
  uint64_t faces = 0;               // faces read (polygons count once)
  uint64_t triangles = 0;           // triangles after fan triangulation, zero-area included
  uint64_t zero_area_dropped = 0;   // triangles with zero area: counted, not sent to the sink
  uint64_t attributes_not_finite = 0;  // normals or texture coordinates with a NaN or inf
  // Faces of 0-2 corners: no surface (exporters write edges and points so), skipped with a
  // count like zero-area triangles. Their indices are still checked.
  uint64_t faces_under_three_corners = 0;
  bool has_normals = false;         // any triangle had normals
  bool has_uvs = false;             // any triangle had texture coordinates
  Bounds3f bounds;                  // of all vertices, referenced or not
};

// Reads an OBJ or PLY file (chosen by content: PLY starts with "ply"; else by extension).
// Triangles go to `sink`; `info` is filled as reading goes (valid on success).
Status ReadModel(const std::string& path, const ReadOptions& options, TriangleSink& sink,
                 ModelInfo* info);

}  // namespace raystack::import
