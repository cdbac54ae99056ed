#pragma once
// Procedural models, for tests and the built-in default scene, delivered through the same
// TriangleSink as the file readers. Every generator is deterministic.
//   sphere:N    a closed, watertight cube-sphere of about N triangles
//   spheres:N   a 4x4 grid of cube-spheres on a floor, about N triangles in all (the default)
//   soup:N      N random triangles in the unit cube (seeded; a stress case, not a surface)
//   cluster:N   N tiny triangles all within 1e-6 of one point (degenerate input)

#include <cstdint>
#include <string>

#include "common/base/status.h"
#include "tools/import/model_reader.h"

namespace raystack::prep {

struct GeneratorSpec {
  std::string kind;  // sphere, spheres, soup or cluster
  uint64_t n = 200000;
};
// "KIND" or "KIND:N" (N 200,000 when left out): an unknown kind, or N outside [1, 4e9], is an
// error naming the spec. (Also how the command line checks --generate before anything runs.)
Expected<GeneratorSpec> ParseGeneratorSpec(const std::string& spec);

// Parses "KIND:N" and streams the model into `sink`; `info` gets the counts.
Status GenerateModel(const std::string& spec, import::TriangleSink& sink, import::ModelInfo* info);

}  // namespace raystack::prep
