#include "tools/import/obj_reader.h"

#include <gtest/gtest.h>

#include "tests/import/import_test_util.h"

namespace raystack::import {
namespace {

// A unit square in z = 0 with texture coordinates and one normal, then one face line.
std::string Square(const std::string& face) {
  return "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
         "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
         "vn 0 0 1\n" +
         face + "\n";
}

struct ObjResult {
  Status status;
  ModelInfo info;
  CollectingSink sink;
};

ObjResult ReadObjText(const ScratchFiles& files, const std::string& text,
                      const ReadOptions& options = {}, const std::string& name = "model.obj") {
  ObjResult result;
  result.status = ReadFile(files.Write(name, text), &result.sink, &result.info, options);
  return result;
}

TEST(ObjReader, ReadsEveryIndexForm) {
  ScratchFiles files;
  struct Case {
    const char* face;
    bool uvs, normals;
  } cases[] = {{"f 1 2 3", false, false},
               {"f 1/1 2/2 3/3", true, false},
               {"f 1//1 2//1 3//1", false, true},
               {"f 1/1/1 2/2/1 3/3/1", true, true}};
  for (const Case& c : cases) {
    ObjResult r = ReadObjText(files, Square(c.face));
    ASSERT_TRUE(r.status.ok()) << r.status.message();
    ASSERT_EQ(r.sink.triangles.size(), 1u) << c.face;
    const SourceTriangle& t = r.sink.triangles[0];
    EXPECT_EQ(t.p[1], (Vec3f{1, 0, 0}));
    EXPECT_EQ(t.has_uvs, c.uvs) << c.face;
    EXPECT_EQ(t.has_normals, c.normals) << c.face;
    EXPECT_EQ(r.info.has_uvs, c.uvs);
    EXPECT_EQ(r.info.has_normals, c.normals);
    if (c.uvs) {
      EXPECT_EQ(t.uv[2][0], 1.0f);
    }
    if (c.normals) {
      EXPECT_EQ(t.n[0], (Vec3f{0, 0, 1}));
    }
    EXPECT_EQ(t.material, kNoMaterial);
  }
}

TEST(ObjReader, NegativeIndicesCountBackFromTheLastVertex) {
  ScratchFiles files;
  ObjResult r = ReadObjText(files, Square("f -4/-4/-1 -3/-3/-1 -2/-2/-1"));
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  ASSERT_EQ(r.sink.triangles.size(), 1u);
  EXPECT_EQ(r.sink.triangles[0].p[0], (Vec3f{0, 0, 0}));
  EXPECT_EQ(r.sink.triangles[0].p[2], (Vec3f{1, 1, 0}));
  EXPECT_EQ(r.sink.triangles[0].uv[1][0], 1.0f);
}

TEST(ObjReader, ConvexPolygonsBecomeFans) {
  ScratchFiles files;
  ObjResult r = ReadObjText(files,
                            "v 0 0 0\nv 1 0 0\nv 2 1 0\nv 1 2 0\nv 0 1 0\n"
                            "f 1 2 3 4 5\nf 1 2 3 4\n");
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  EXPECT_EQ(r.info.faces, 2u);
  EXPECT_EQ(r.info.triangles, 5u);
  ASSERT_EQ(r.sink.triangles.size(), 5u);
  for (int i = 0; i < 2; ++i) {  // (1 2 3) (1 3 4) (1 4 5)
    EXPECT_EQ(r.sink.triangles[i].p[0], (Vec3f{0, 0, 0}));
    EXPECT_EQ(r.sink.triangles[i].p[2], r.sink.triangles[i + 1].p[1]);
  }
  EXPECT_EQ(r.sink.triangles[2].p[0], (Vec3f{0, 0, 0}));
  EXPECT_EQ(r.sink.triangles[2].p[2], (Vec3f{0, 1, 0}));
}

// An L-shaped face listed from its notch's corner (as Blender writes n-gons): its fan covered
// the notch with a triangle outside the face (found by a helper converting exporters' files).
TEST(ObjReader, AConcavePolygonIsSplitInsideItself) {
  ScratchFiles files;
  ObjResult r = ReadObjText(files,
                            "v 2 1 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\nv 0 0 0\nv 2 0 0\n"
                            "vn 0 0 1\nf 1//1 2//1 3//1 4//1 5//1 6//1\n");
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  ASSERT_EQ(r.sink.triangles.size(), 4u);
  float area = 0;
  for (const SourceTriangle& t : r.sink.triangles) {
    const Vec3f n = Cross(t.p[1] - t.p[0], t.p[2] - t.p[0]);
    EXPECT_GT(n.z, 0) << "the face's winding is kept";
    area += 0.5f * n.z;
    const Vec3f c = (t.p[0] + t.p[1] + t.p[2]) * (1.0f / 3);
    EXPECT_FALSE(c.x > 1 && c.y > 1) << "a triangle in the notch";
    EXPECT_TRUE(t.has_normals);
  }
  EXPECT_FLOAT_EQ(area, 3.0f);
}

TEST(ObjReader, ToleratesCrlfTabsCommentsGroupsAndContinuations) {
  ScratchFiles files;
  ObjResult r = ReadObjText(files,
                            "\xEF\xBB\xBF# header, after a UTF-8 byte order mark\r\n"
                            "o thing\r\n"
                            "g part:1%2\r\n"
                            "s off\r\n"
                            "v\t 0  0\t0 \r\n"
                            "v 1 0 0 1.0   # with w\r\n"
                            "v 1 1 0 0.5 0.5 0.5\r\n"
                            "\r\n"
                            "   \t\r\n"
                            "f 1 \\\r\n"
                            "  2 \\\r\n"
                            "  3\r\n"
                            "l 1 2\r\n"
                            "vp 0.5\r\n"
                            "f 3 2 1");  // no final newline
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  EXPECT_EQ(r.info.vertices, 3u);
  EXPECT_EQ(r.info.triangles, 2u);
  ASSERT_EQ(r.sink.triangles.size(), 2u);
  EXPECT_EQ(r.sink.triangles[0].p[2], (Vec3f{1, 1, 0}));
  EXPECT_EQ(r.info.bounds.upper, (Vec3f{1, 1, 0}));
}

// Found by a helper converting exporters' files: Blender writes `mtllib my model.mtl` (a name
// with a space, unquoted), and every material was lost; two OBJ files concatenated name their
// library twice, and every material was "defined again"; a comment ending in a backslash (a
// Windows path) swallowed the next line, a vertex.
TEST(ObjReader, ExportersLibraryNamesAndCommentsAreReadAsTheyMeanThem) {
  ScratchFiles files;
  files.Write("my model.mtl", "newmtl Red Paint\nKd 1 0 0\n");
  testing::internal::CaptureStderr();
  ObjResult r = ReadObjText(files,
                            "mtllib my model.mtl\nmtllib my model.mtl\n"
                            "# Exported from D:\\Projects\\\n"
                            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\n"
                            "usemtl Red Paint\nf 1 2 3\n");
  const std::string err = testing::internal::GetCapturedStderr();
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  EXPECT_EQ(err.find("defined again"), std::string::npos) << err;
  EXPECT_EQ(r.info.vertices, 4u);
  ASSERT_EQ(r.sink.triangles.size(), 1u);
  EXPECT_EQ(r.sink.triangles[0].p[0], (Vec3f{0, 0, 0}));
  ASSERT_EQ(r.info.materials.size(), 1u);
  EXPECT_EQ(r.info.materials[0].name, "Red Paint");
  EXPECT_EQ(r.info.materials[0].kd, (Vec3f{1, 0, 0}));
  EXPECT_FALSE(r.info.materials[0].defined_at.empty());
}

// Normals or texture coordinates that are not finite ("nan", 3ds Max's "-1.#IND" for a
// degenerate face) stopped the whole conversion; they are optional data: the faces that use
// them go without, and they are counted. A comment after a normal is still a comment.
TEST(ObjReader, NonFiniteNormalsAndUvsAreDroppedNotFatal) {
  ScratchFiles files;
  ObjResult r = ReadObjText(files,
                            "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
                            "vn -1.#IND -1.#IND -1.#IND\nvn nan 0 1\nvn 0 0 1 # up\n"
                            "vt 0 inf\nvt 1 1\n"
                            "f 1//1 2//1 3//1\nf 1//2 2//2 3//2\nf 1/2/3 2/2/3 3/2/3\n"
                            "f 1/1/3 2/2/3 3/2/3\n");
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  EXPECT_EQ(r.info.attributes_not_finite, 3u);
  ASSERT_EQ(r.sink.triangles.size(), 4u);
  EXPECT_FALSE(r.sink.triangles[0].has_normals);
  EXPECT_FALSE(r.sink.triangles[1].has_normals);
  EXPECT_TRUE(r.sink.triangles[2].has_normals);
  EXPECT_EQ(r.sink.triangles[2].n[0], (Vec3f{0, 0, 1}));
  EXPECT_TRUE(r.sink.triangles[2].has_uvs);
  EXPECT_FALSE(r.sink.triangles[3].has_uvs);
  // Positions stay strict: a vertex that is not finite is an error naming its line, in MSVC's
  // spelling too (it was read as "-1." and a comment: z = -1).
  ExpectErrorMentions(ReadObjText(files, "v nan 0 0\n").status, {"model.obj:1:", "not finite"});
  ExpectErrorMentions(ReadObjText(files, "v 0 1 -1.#IND\n").status, {"model.obj:1:", "-1.#IND"});
}

// --shift: a georeferenced model (a 3 cm triangle at UTM coordinates, whose float steps are
// 0.5 m) keeps its shape when its positions are shifted in double before they become floats;
// automatic takes the first vertex, rounded, and keeps it for the rest.
TEST(ObjReader, AShiftKeepsTheDetailOfAModelFarFromTheOrigin) {
  ScratchFiles files;
  const std::string far =
      "v 500123.25 5400456.50 312.00\nv 500123.28 5400456.50 312.00\nv 500123.25 5400456.53 312.00\n"
      "f 1 2 3\n";
  ObjResult flat = ReadObjText(files, far);
  ASSERT_TRUE(flat.status.ok()) << flat.status.message();
  EXPECT_TRUE(flat.sink.triangles.empty());  // without a shift: no area left
  PositionShift automatic;
  automatic.automatic = true;
  ReadOptions options;
  options.shift = &automatic;
  ObjResult kept = ReadObjText(files, far, options);
  ASSERT_TRUE(kept.status.ok()) << kept.status.message();
  ASSERT_EQ(kept.sink.triangles.size(), 1u);
  EXPECT_EQ(automatic.by[0], 500123.0);
  EXPECT_EQ(automatic.by[1], 5400457.0);  // 5400456.5 rounded away from zero
  EXPECT_EQ(automatic.by[2], 312.0);
  EXPECT_NEAR(kept.sink.triangles[0].p[1].x - kept.sink.triangles[0].p[0].x, 0.03f, 1e-6f);
  EXPECT_NEAR(kept.sink.triangles[0].p[0].y, -0.5f, 1e-6f);
  // A shift given is used as it is.
  PositionShift given;
  given.set = true;
  given.by[0] = 500000;
  given.by[1] = 5400000;
  options.shift = &given;
  kept = ReadObjText(files, far, options);
  ASSERT_EQ(kept.sink.triangles.size(), 1u);
  EXPECT_NEAR(kept.sink.triangles[0].p[0].x, 123.25f, 1e-4f);
  EXPECT_NEAR(kept.sink.triangles[0].p[0].z, 312.0f, 1e-4f);
}

TEST(ObjReader, MaterialsComeFromSeveralLibrariesNextToTheObj) {
  ScratchFiles files;
  files.Write("a.mtl", "newmtl red\nKd 1 0 0\n");
  files.Write("b.mtl", "newmtl light\nKe 5 5 5\n");
  ObjResult r = ReadObjText(files,
                            "mtllib a.mtl missing.mtl b.mtl\n"
                            "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
                            "f 1 2 3\n"
                            "usemtl light\nf 1 2 3\n"
                            "usemtl red\nf 1 2 3\n"
                            "usemtl ghost\nf 1 2 3\n");
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  ASSERT_EQ(r.sink.triangles.size(), 4u);
  const std::vector<Material>& m = r.info.materials;
  ASSERT_EQ(m.size(), 3u);
  EXPECT_EQ(r.sink.triangles[0].material, kNoMaterial);
  EXPECT_EQ(m[r.sink.triangles[1].material].name, "light");
  EXPECT_EQ(m[r.sink.triangles[1].material].ke, (Vec3f{5, 5, 5}));
  EXPECT_EQ(m[r.sink.triangles[2].material].kd, (Vec3f{1, 0, 0}));
  EXPECT_EQ(m[r.sink.triangles[3].material].name, "ghost");
  EXPECT_EQ(m[r.sink.triangles[3].material].kd, Material{}.kd);
}

TEST(ObjReader, MalformedMaterialLibraryIsAnError) {
  ScratchFiles files;
  files.Write("bad.mtl", "newmtl x\nKd 1 inf 0\n");
  ObjResult r = ReadObjText(files, "mtllib bad.mtl\nv 0 0 0\n");
  ExpectErrorMentions(r.status, {"bad.mtl:2:"});
}

TEST(ObjReader, ZeroAreaTrianglesAreCountedNotSent) {
  ScratchFiles files;
  ObjResult r = ReadObjText(files,
                            "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\n"
                            "f 1 2 3\nf 1 1 4\nf 1 2 4\n");
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  EXPECT_EQ(r.info.triangles, 3u);
  EXPECT_EQ(r.info.zero_area_dropped, 2u);
  EXPECT_EQ(r.sink.triangles.size(), 1u);
}

TEST(ObjReader, BatchesAreFullExceptTheLast) {
  ScratchFiles files;
  std::string text = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  for (int i = 0; i < 10'000; ++i) text += "f 1 2 3\n";
  ObjResult r = ReadObjText(files, text);
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  EXPECT_EQ(r.sink.triangles.size(), 10'000u);
  EXPECT_EQ(r.sink.batches, 3);
}

TEST(ObjReader, SpilledVerticesGiveIdenticalTriangles) {
  ScratchFiles files;
  std::string text;
  const int kSide = 120;  // 14,400 vertices, 28,322 triangles
  for (int y = 0; y < kSide; ++y)
    for (int x = 0; x < kSide; ++x)
      text += "v " + std::to_string(x) + " " + std::to_string(y) + " " +
              std::to_string((x * y) % 7) + "\nvt 0." + std::to_string(x) + " 0." +
              std::to_string(y) + "\n";
  for (int y = 0; y + 1 < kSide; ++y)
    for (int x = 0; x + 1 < kSide; ++x) {
      int a = y * kSide + x + 1, b = a + 1, c = a + kSide + 1, d = a + kSide;
      auto ref = [](int i) { return std::to_string(i) + "/" + std::to_string(i); };
      text += "f " + ref(a) + " " + ref(b) + " " + ref(c) + " " + ref(d) + "\n";
    }
  std::string path = files.Write("grid.obj", text);
  CollectingSink in_memory, spilled;
  ModelInfo info_memory, info_spilled;
  ASSERT_TRUE(ReadFile(path, &in_memory, &info_memory).ok());
  ReadOptions tiny;
  tiny.vertex_memory_bytes = 4096;
  tiny.temp_dir = files.path();
  ASSERT_TRUE(ReadFile(path, &spilled, &info_spilled, tiny).ok());
  ASSERT_EQ(in_memory.triangles.size(), spilled.triangles.size());
  EXPECT_EQ(info_memory.triangles, 2u * (kSide - 1) * (kSide - 1));
  for (size_t i = 0; i < spilled.triangles.size(); ++i)
    ASSERT_TRUE(SameTriangle(in_memory.triangles[i], spilled.triangles[i])) << i;
}

TEST(ObjReader, SinkErrorStopsTheReader) {
  struct FailingSink : TriangleSink {
    Status Consume(std::span<const SourceTriangle>) override {
      return Status::Error("disk full");
    }
  } sink;
  ScratchFiles files;
  ModelInfo info;
  Status status = ReadModel(files.Write("a.obj", Square("f 1 2 3")), {}, sink, &info);
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.message(), "disk full");
}

TEST(ObjReader, TriangleCapIsAnError) {
  ScratchFiles files;
  ReadOptions options;
  options.max_triangles = 3;
  ObjResult r = ReadObjText(files, Square("f 1 2 3 4\nf 1 2 3 4"), options);
  ExpectErrorMentions(r.status, {"model.obj:11:", "more than 3 triangles"});
}

// Every malformed input: an error naming the file and the line.
// Faces of 0-2 corners (edges and points, as some exporters write them) have no surface: they are
// skipped with a count, and the faces around them are read as usual.
TEST(ObjReader, FacesOfFewerThanThreeCornersAreSkippedWithACount) {
  ScratchFiles files;
  ObjResult r = ReadObjText(files, "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                   "f 1 2\nf 1 2 3\nf 3\nf\nf 2 3\nf 3 2 1\n");
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  EXPECT_EQ(r.info.faces, 2u);
  EXPECT_EQ(r.info.faces_under_three_corners, 4u);
  EXPECT_EQ(r.sink.triangles.size(), 2u);
}

TEST(ObjReader, MalformedInputNamesFileAndLine) {
  ScratchFiles files;
  struct Case {
    std::string text;
    std::vector<std::string> mentions;
  } cases[] = {
      {Square("f 1 2 99"), {"model.obj:10:", "face index 99 out of range", "4 vertices"}},
      {Square("f 1 2 -5"), {"model.obj:10:", "face index -5 out of range"}},
      {Square("f 0 1 2"), {"model.obj:10:", "face index 0"}},
      {Square("f 1/9 2/1 3/1"), {"model.obj:10:", "texture index 9"}},
      {Square("f 1//2 2//1 3//1"), {"model.obj:10:", "normal index 2"}},
      {Square("f 1/1/1/1 2 3"), {"model.obj:10:", "'1/1/1/1' has more than 3 indices"}},
      {Square("f 1 9"), {"model.obj:10:", "face index 9 out of range"}},  // an edge's too
      {Square("f 1 2 x"), {"model.obj:10:", "'x'"}},
      {Square("f 1 2 3.5"), {"model.obj:10:"}},
      {"v 0 0 0\nv nan 0 0\n", {"model.obj:2:", "nan"}},
      {"v 0 0 0\nv 1 inf 0\n", {"model.obj:2:", "inf"}},
      {"v 0 0 0\nv 1 1e39 0\n", {"model.obj:2:", "float range"}},
      {"v 0 0 0\nv 1 -2e18 0\n", {"model.obj:2:", "beyond +-1e18"}},  // products overflow float
      {"v 0 0 0\r\nv 1 2", {"model.obj:2:", "expected 3 numbers, found 2"}},
      {"vn 1 2\n", {"model.obj:1:", "expected 3"}},
      {"vt\n", {"model.obj:1:"}},
      {"v 1 2 3\n\x01\x02\xff\xfe garbage\n", {"model.obj:2:", "not an OBJ statement"}},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.text);
    ObjResult r = ReadObjText(files, c.text);
    ExpectErrorMentions(r.status, c.mentions);
  }
}

}  // namespace
}  // namespace raystack::import
