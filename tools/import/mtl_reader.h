#pragma once
// Wavefront MTL materials: only what a ray tracer uses (Kd, Ks, Ke, Ni, d or Tr, illum).
// Other statements (maps, Ns, Ka, ...) are ignored.

#include <cstdint>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "common/base/status.h"
#include "tools/import/buffered_input.h"
#include "tools/import/model_reader.h"

namespace raystack::import {

// The materials of one model by name, filled by `newmtl` (MTL) and `usemtl` (OBJ) in any
// order: a name used before (or without) its definition gets a default entry, which a later
// definition fills in place, so indices handed out never change.
class MaterialTable {
 public:
  // Index for `usemtl name`.
  uint32_t Use(std::string_view name);
  // The entry a `newmtl name` block fills; nullptr if an MTL defined `name` already.
  Material* Define(std::string_view name);
  // Where `name`'s newmtl is ("file.mtl:12"); empty when no MTL defined it.
  std::string DefinedAt(std::string_view name) const;
  // Names used but defined by no MTL (they keep the default material).
  std::vector<std::string> UndefinedNames() const;
  // Moves the materials out, indexed as Use() answered.
  std::vector<Material> Take() { return std::move(materials_); }

 private:
  uint32_t Add(std::string_view name);

  std::vector<Material> materials_;
  std::vector<bool> defined_;
  std::unordered_map<std::string, uint32_t> index_;
};

// Reads one MTL file into `table`. Malformed numbers are errors naming the file and line.
Status ReadMtl(BufferedInput& input, MaterialTable* table);

}  // namespace raystack::import
