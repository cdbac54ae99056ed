#pragma once
// PLY (ascii, binary little and big endian), streamed. The vertex element may have any
// property layout: x, y, z are required; nx, ny, nz give normals; u, v (or s, t, or
// texture_u, texture_v) give texture coordinates. Faces are the list property vertex_indices
// (or vertex_index) of element face, with any integer count and index types; polygons are
// fan-triangulated. Other elements and properties are read and skipped. Faces must come after
// the vertices (as every writer puts them); the other order is reported as not supported.

#include "common/base/status.h"
#include "tools/import/buffered_input.h"
#include "tools/import/model_reader.h"

namespace raystack::import {

// Reads the PLY behind `input` (opened by ReadModel); the contract is ReadModel's.
Status ReadPly(BufferedInput& input, const ReadOptions& options, TriangleSink& sink,
               ModelInfo* info);

}  // namespace raystack::import
