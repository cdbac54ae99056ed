#pragma once
// Wavefront OBJ, streamed: `v`, `vt`, `vn` go to vertex tables (RAM within the budget, disk
// beyond), each `f` is resolved and fan-triangulated as soon as it is read. Indices may be
// positive or negative (relative), in the forms v, v/vt, v//vn and v/vt/vn. `usemtl` selects
// a material from the `mtllib` files (found next to the OBJ); `o`, `g`, `s` are accepted and
// ignored; other statements are skipped with one warning per keyword. A line ending in '\'
// continues on the next one.

#include "common/base/status.h"
#include "tools/import/buffered_input.h"
#include "tools/import/model_reader.h"

namespace raystack::import {

// Reads the OBJ behind `input` (opened by ReadModel); the contract is ReadModel's.
Status ReadObj(BufferedInput& input, const ReadOptions& options, TriangleSink& sink,
               ModelInfo* info);

}  // namespace raystack::import
