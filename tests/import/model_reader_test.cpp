#include "tools/import/model_reader.h"

#include <gtest/gtest.h>

#include "common/base/progress.h"
#include "tests/import/import_test_util.h"

namespace raystack::import {
namespace {

const std::string kCornellBox = std::string(RAYSTACK_TEST_DATA) + "/CornellBox-Original.obj";

TEST(ModelReader, CornellBoxHasItsMaterialsAndAnEmitter) {
  CollectingSink sink;
  ModelInfo info;
  Status status = ReadFile(kCornellBox, &sink, &info);
  ASSERT_TRUE(status.ok()) << status.message();
  EXPECT_EQ(info.vertices, 72u);
  EXPECT_EQ(info.faces, 18u);
  EXPECT_EQ(info.triangles, 36u);
  EXPECT_EQ(sink.triangles.size(), 36u);
  ASSERT_EQ(info.materials.size(), 8u);
  std::vector<bool> used(info.materials.size(), false);
  for (const SourceTriangle& t : sink.triangles) {
    ASSERT_LT(t.material, info.materials.size());
    used[t.material] = true;
  }
  EXPECT_EQ(std::count(used.begin(), used.end(), true), 8);
  int emitters = 0;
  for (const Material& m : info.materials) {
    if (m.ke.x > 0 && m.ke.y > 0 && m.ke.z > 0) {
      ++emitters;
      EXPECT_EQ(m.name, "light");
      EXPECT_EQ(m.ke, (Vec3f{17, 12, 4}));
    }
  }
  EXPECT_EQ(emitters, 1);
  EXPECT_EQ(info.bounds.lower, (Vec3f{-1.02f, 0, -1.04f}));
  EXPECT_EQ(info.bounds.upper, (Vec3f{1, 1.99f, 0.99f}));
}

TEST(ModelReader, ChoosesPlyByContentAndObjByExtension) {
  ScratchFiles files;
  const std::string ply =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  for (const char* name : {"a.ply", "a.dat", "a.obj"}) {
    CollectingSink sink;
    ModelInfo info;
    ASSERT_TRUE(ReadFile(files.Write(name, ply), &sink, &info).ok()) << name;
    EXPECT_EQ(sink.triangles.size(), 1u) << name;
  }
  CollectingSink sink;
  ModelInfo info;
  ASSERT_TRUE(ReadFile(files.Write("A.OBJ", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"), &sink, &info)
                  .ok());
  EXPECT_EQ(sink.triangles.size(), 1u);
}

TEST(ModelReader, RejectsWhatItCannotReadNamingTheFile) {
  ScratchFiles files;
  CollectingSink sink;
  ModelInfo info;
  ExpectErrorMentions(ReadFile(files.Write("mesh.stl", "solid x\n"), &sink, &info),
                      {"mesh.stl", "unknown model format"});
  ExpectErrorMentions(ReadFile(files.Write("empty.obj", ""), &sink, &info),
                      {"empty.obj", "empty"});
  ExpectErrorMentions(ReadFile(files.Write("empty.ply", ""), &sink, &info),
                      {"empty.ply", "empty"});
  ExpectErrorMentions(ReadFile(files.path() + "/absent.obj", &sink, &info), {"absent.obj"});
  ExpectErrorMentions(ReadFile(files.path(), &sink, &info), {files.path()});
}

TEST(ModelReader, ReadsWithAProgressReporter) {
  ProgressReporter progress("read", 0, "B", /*quiet=*/true);
  ReadOptions options;
  options.progress = &progress;
  CollectingSink sink;
  ModelInfo info;
  EXPECT_TRUE(ReadModel(kCornellBox, options, sink, &info).ok());
}

}  // namespace
}  // namespace raystack::import
