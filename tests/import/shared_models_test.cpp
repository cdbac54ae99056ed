// The real models in RAYSTACK_SHARED_MODELS load with the counts and bounds of their
// MANIFEST.tsv. Skipped, saying so, where the folder is absent (a fresh clone).

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "tests/import/import_test_util.h"

namespace raystack::import {
namespace {

// (RAYSTACK_SHARED_MODELS in the environment, as every real-model test takes it.)
const std::string kModels = [] {
  const char* env = std::getenv("RAYSTACK_SHARED_MODELS");
  return std::string(env && *env ? env : RAYSTACK_SHARED_MODELS);
}();

// Counts triangles and checks material indices without keeping them.
class CountingSink : public TriangleSink {
 public:
  Status Consume(std::span<const SourceTriangle> batch) override {
    received += batch.size();
    for (const SourceTriangle& t : batch)
      if (t.material != kNoMaterial && t.material > max_material) max_material = t.material;
    return OkStatus();
  }
  uint64_t received = 0;
  uint32_t max_material = 0;
};

// MANIFEST.tsv rows as column name -> value.
std::vector<std::map<std::string, std::string>> ReadManifest(const std::string& path) {
  std::ifstream in(path);
  std::vector<std::map<std::string, std::string>> rows;
  std::vector<std::string> columns;
  std::string line;
  while (std::getline(in, line)) {
    std::vector<std::string> fields;
    std::stringstream split(line);
    for (std::string field; std::getline(split, field, '\t');) fields.push_back(field);
    if (columns.empty()) {
      columns = fields;
      continue;
    }
    std::map<std::string, std::string> row;
    for (size_t i = 0; i < columns.size() && i < fields.size(); ++i) row[columns[i]] = fields[i];
    rows.push_back(row);
  }
  return rows;
}

void ExpectClose(float actual, const std::string& expected, const std::string& what) {
  double want = std::stod(expected);
  double tolerance = 1e-4 * std::max(std::fabs(want), 1e-3);
  EXPECT_NEAR(static_cast<double>(actual), want, tolerance) << what;
}

TEST(SharedModels, LoadWithManifestCountsAndBounds) {
  if (!std::filesystem::is_directory(kModels)) {
    std::string message = "shared models folder " + kModels +
                          " not found; set RAYSTACK_SHARED_MODELS=<folder> (or configure with "
                          "-DRAYSTACK_SHARED_MODELS=<folder>) to run";
    std::printf("%s\n", message.c_str());
    GTEST_SKIP() << message;
  }
  auto rows = ReadManifest(kModels + "/MANIFEST.tsv");
  ASSERT_FALSE(rows.empty()) << "empty or missing " << kModels << "/MANIFEST.tsv";
  for (auto& row : rows) {
    const std::string& file = row["file"];
    SCOPED_TRACE(file);
    CountingSink sink;
    ModelInfo info;
    Status status = ReadModel(kModels + "/" + file, {}, sink, &info);
    ASSERT_TRUE(status.ok()) << status.message();
    EXPECT_EQ(info.triangles, std::stoull(row["triangles"]));
    EXPECT_EQ(info.vertices, std::stoull(row["vertices"]));
    EXPECT_EQ(sink.received + info.zero_area_dropped, info.triangles);
    const char* axes = "xyz";
    for (int a = 0; a < 3; ++a) {
      std::string axis(1, axes[a]);
      ExpectClose(info.bounds.lower[a], row["bbox_min_" + axis], "min " + axis);
      ExpectClose(info.bounds.upper[a], row["bbox_max_" + axis], "max " + axis);
    }
    if (!info.materials.empty()) {
      EXPECT_LT(sink.max_material, info.materials.size());
    }
    // The README: the dragon has 108 collinear triangles, no other model has any.
    EXPECT_EQ(info.zero_area_dropped, file == "dragon_vrip.ply" ? 108u : 0u);
    if (file == "CornellBox-Original.obj") {
      EXPECT_EQ(info.materials.size(), 8u);
    }
  }
}

}  // namespace
}  // namespace raystack::import
