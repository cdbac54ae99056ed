#pragma once
// Test helpers: load a model's triangles in the order the converter numbers them (zero-area
// triangles are dropped by the readers, so ids are positions in this list), and locate the
// optional shared real models.

#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "tests/support/brute_force.h"
#include "tools/import/model_reader.h"
#include "tools/prep/generator.h"

namespace raystack::testing {

class CollectSink : public import::TriangleSink {
 public:
  Status Consume(std::span<const import::SourceTriangle> batch) override {
    for (const auto& s : batch) tris.push_back({{s.p[0], s.p[1], s.p[2]}});
    return OkStatus();
  }
  std::vector<Tri> tris;
};

inline std::vector<Tri> LoadTriangles(const std::string& path) {
  CollectSink sink;
  import::ModelInfo info;
  Status s = import::ReadModel(path, import::ReadOptions{}, sink, &info);
  if (!s.ok()) return {};
  return std::move(sink.tris);
}

inline std::vector<Tri> GenerateTriangles(const std::string& spec) {
  CollectSink sink;
  import::ModelInfo info;
  Status s = prep::GenerateModel(spec, sink, &info);
  if (!s.ok()) return {};
  return std::move(sink.tris);
}

// The shared real models folder, or "" when this checkout has none (a fresh clone).
inline std::string SharedModels() {
  const char* env = std::getenv("RAYSTACK_SHARED_MODELS");
  std::string dir = env && *env ? env : RAYSTACK_SHARED_MODELS;
  return std::filesystem::exists(dir + "/MANIFEST.tsv") ? dir : "";
}

}  // namespace raystack::testing
