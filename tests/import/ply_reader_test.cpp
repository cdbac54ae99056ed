#include "tools/import/ply_reader.h"

#include <gtest/gtest.h>

#include <cmath>

#include <limits>

#include "tests/import/import_test_util.h"
#include "tests/import/ply_test_builder.h"

namespace raystack::import {
namespace {

const char* const kFormats[] = {"ascii", "binary_little_endian", "binary_big_endian"};

// A unit square as a quad plus a triangle, with properties in an unusual order, normals,
// s/t texture coordinates, lists where nobody expects them and elements to skip.
std::vector<TestPlyElement> OddSquare() {
  TestPlyElement vertex{"vertex",
                        {{"uchar", "red", ""},
                         {"float", "z", ""},
                         {"double", "x", ""},
                         {"short", "flag", ""},
                         {"float", "y", ""},
                         {"int", "junk", "uchar"},
                         {"float", "nx", ""},
                         {"float", "ny", ""},
                         {"float", "nz", ""},
                         {"float32", "s", ""},
                         {"float64", "t", ""}},
                        {}};
  const double xy[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  for (int i = 0; i < 4; ++i)
    vertex.rows.push_back({200, 0.5, xy[i][0], -3, xy[i][1], 2, 7, 8, 0, 0, 1,
                           xy[i][0] * 0.5, xy[i][1] * 0.25});
  TestPlyElement edge{"edge", {{"int", "vertex1", ""}, {"int", "vertex2", ""}},
                      {{0, 1}, {1, 2}}};
  TestPlyElement face{"face",
                      {{"int", "material_id", ""},
                       {"uint", "vertex_index", "ushort"},
                       {"float", "quality", ""}},
                      {{5, 4, 0, 1, 2, 3, 0.5}, {6, 3, 0, 2, 3, 1.5}}};
  TestPlyElement tail{"material", {{"uchar", "name", "uint"}}, {{3, 65, 66, 67}, {0}}};
  return {vertex, edge, face, tail};
}

// A 2 x 3 grid of vertices (z = 0) as triangle strips, the way Stanford's tools write them:
// one record, strips separated by -1 ({0 3 1 4 2 5}: four triangles, all facing +z).
std::vector<TestPlyElement> StripGrid() {
  TestPlyElement vertex{"vertex", {{"float", "x", ""}, {"float", "y", ""}, {"float", "z", ""}}, {}};
  for (int i = 0; i < 6; ++i) vertex.rows.push_back({double(i % 3), double(i / 3), 0});
  TestPlyElement strips{"tristrips", {{"int", "vertex_indices", "int"}},
                        {{9, 3, 0, 4, 1, 5, 2, -1, 0, 1}}};  // ends with a strip too short
  return {vertex, strips};
}

struct PlyResult {
  Status status;
  ModelInfo info;
  CollectingSink sink;
};

PlyResult ReadPlyText(const ScratchFiles& files, const std::string& bytes,
                      const std::string& name = "m.ply") {
  PlyResult result;
  result.status = ReadFile(files.Write(name, bytes), &result.sink, &result.info);
  return result;
}

// Triangle strips give their triangles, every one facing the same way (Stanford's
// tristrips element used to be skipped without a word).
TEST(PlyReader, TriangleStripsGiveTheirTrianglesFacingOneWay) {
  ScratchFiles files;
  for (const char* format : kFormats) {
    SCOPED_TRACE(format);
    PlyResult r = ReadPlyText(files, TestPlyWriter::Build(format, StripGrid()));
    ASSERT_TRUE(r.status.ok()) << r.status.message();
    ASSERT_EQ(r.sink.triangles.size(), 4u);
    for (const SourceTriangle& t : r.sink.triangles)
      EXPECT_GT(Cross(t.p[1] - t.p[0], t.p[2] - t.p[0]).z, 0) << "turned over";
    EXPECT_EQ(r.sink.triangles[1].p[0], (Vec3f{1, 1, 0}));  // (4 0 1): the second, turned
  }
  // With an unsigned index type, -1 is written as its largest value.
  std::vector<TestPlyElement> unsigned_strips = StripGrid();
  unsigned_strips[1].properties[0] = {"uint", "vertex_indices", "uint"};
  unsigned_strips[1].rows[0][7] = 4294967295.0;
  PlyResult r = ReadPlyText(files, TestPlyWriter::Build("binary_little_endian", unsigned_strips));
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  EXPECT_EQ(r.sink.triangles.size(), 4u);
}

TEST(PlyReader, ReadsAnyLayoutInEveryFormatAlike) {
  ScratchFiles files;
  std::vector<SourceTriangle> first;
  for (const char* format : kFormats) {
    SCOPED_TRACE(format);
    PlyResult r = ReadPlyText(files, TestPlyWriter::Build(format, OddSquare()));
    ASSERT_TRUE(r.status.ok()) << r.status.message();
    EXPECT_EQ(r.info.vertices, 4u);
    EXPECT_EQ(r.info.faces, 2u);
    EXPECT_EQ(r.info.triangles, 3u);
    EXPECT_TRUE(r.info.has_normals);
    EXPECT_TRUE(r.info.has_uvs);
    EXPECT_EQ(r.info.bounds.lower, (Vec3f{0, 0, 0.5f}));
    EXPECT_EQ(r.info.bounds.upper, (Vec3f{1, 1, 0.5f}));
    ASSERT_EQ(r.sink.triangles.size(), 3u);
    const SourceTriangle& t = r.sink.triangles[1];  // (0 2 3) of the quad
    EXPECT_EQ(t.p[1], (Vec3f{1, 1, 0.5f}));
    EXPECT_EQ(t.n[2], (Vec3f{0, 0, 1}));
    EXPECT_EQ(t.uv[1][0], 0.5f);
    EXPECT_EQ(t.uv[1][1], 0.25f);
    EXPECT_EQ(t.material, kNoMaterial);
    if (first.empty()) first = r.sink.triangles;
    for (size_t i = 0; i < first.size(); ++i)
      EXPECT_TRUE(SameTriangle(first[i], r.sink.triangles[i])) << i;
  }
}

TEST(PlyReader, AcceptsEveryIntegerCountAndIndexType) {
  const std::pair<const char*, const char*> kTypes[] = {
      {"uchar", "int"},  {"ushort", "uint"}, {"int", "short"},    {"char", "uint8"},
      {"uint8", "int16"}, {"int32", "uint32"}, {"uint16", "ushort"}, {"short", "char"}};
  ScratchFiles files;
  for (const char* format : kFormats) {
    for (auto [count_type, index_type] : kTypes) {
      SCOPED_TRACE(std::string(format) + " " + count_type + " " + index_type);
      TestPlyElement vertex{"vertex",
                            {{"float", "x", ""}, {"float", "y", ""}, {"float", "z", ""}},
                            {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}};
      TestPlyElement face{"face", {{index_type, "vertex_indices", count_type}},
                          {{3, 0, 1, 2}, {3, 0, 2, 3}}};
      PlyResult r = ReadPlyText(files, TestPlyWriter::Build(format, {vertex, face}));
      ASSERT_TRUE(r.status.ok()) << r.status.message();
      ASSERT_EQ(r.sink.triangles.size(), 2u);
      EXPECT_EQ(r.sink.triangles[1].p[2], (Vec3f{0, 1, 0}));
      EXPECT_FALSE(r.info.has_normals);
    }
  }
}

TEST(PlyReader, ReadsCrlfHeadersAndBlankAsciiLines) {
  ScratchFiles files;
  PlyResult r = ReadPlyText(files,
                            "ply\r\nformat ascii 1.0\r\nobj_info scanner\r\n"
                            "element vertex 3\r\nproperty float x\r\nproperty float y\r\n"
                            "property float z\r\nelement face 1\r\n"
                            "property list uchar int vertex_indices\r\nend_header\r\n"
                            "0 0 0 \r\n1 0 0\r\n\r\n0 1 0\r\n3 0 1 2\r\n");
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  EXPECT_EQ(r.sink.triangles.size(), 1u);
}

TEST(PlyReader, PointCloudWithoutFacesIsFine) {
  ScratchFiles files;
  TestPlyElement vertex{"vertex", {{"float", "x", ""}, {"float", "y", ""}, {"float", "z", ""}},
                        {{0, 0, 0}, {1, 2, 3}}};
  PlyResult r = ReadPlyText(files, TestPlyWriter::Build("binary_little_endian", {vertex}));
  ASSERT_TRUE(r.status.ok()) << r.status.message();
  EXPECT_EQ(r.info.vertices, 2u);
  EXPECT_EQ(r.info.triangles, 0u);
  EXPECT_EQ(r.info.bounds.upper, (Vec3f{1, 2, 3}));
}

// Faces of 0-2 corners (edges and points, as some exporters write them) have no surface: they are
// skipped with a count, in every format, and the faces around them are read as usual.
TEST(PlyReader, FacesOfFewerThanThreeCornersAreSkippedWithACount) {
  ScratchFiles files;
  for (const char* format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
    SCOPED_TRACE(format);
    TestPlyElement vertex{"vertex", {{"float", "x", ""}, {"float", "y", ""}, {"float", "z", ""}},
                          {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}};
    TestPlyElement faces{"face", {{"int", "vertex_indices", "uchar"}},
                         {{2, 0, 1}, {3, 0, 1, 2}, {0}, {1, 2}, {3, 2, 1, 0}}};
    PlyResult r = ReadPlyText(files, TestPlyWriter::Build(format, {vertex, faces}));
    ASSERT_TRUE(r.status.ok()) << r.status.message();
    EXPECT_EQ(r.info.faces, 2u);
    EXPECT_EQ(r.info.faces_under_three_corners, 3u);
    EXPECT_EQ(r.sink.triangles.size(), 2u);
  }
}

// A triangle whose vertex data and face data can be damaged one way at a time.
std::string Triangle(const std::string& format, std::vector<double> face,
                     double y1 = 0, std::optional<uint64_t> declared_faces = std::nullopt,
                     const std::string& index_type = "int") {
  TestPlyElement vertex{"vertex", {{"float", "x", ""}, {"float", "y", ""}, {"float", "z", ""}},
                        {{0, 0, 0}, {1, y1, 0}, {0, 1, 0}}};
  TestPlyElement faces{"face", {{index_type, "vertex_indices", "uchar"}}, {std::move(face)},
                       declared_faces};
  return TestPlyWriter::Build(format, {vertex, faces});
}

// The header of Triangle(): where its body starts, for byte offsets.
size_t BodyStart(const std::string& file) { return file.find("end_header\n") + 11; }

TEST(PlyReader, AsciiErrorsNameFileAndLine) {
  ScratchFiles files;
  // Header lines 1-10, vertices on lines 11-13, the face on line 14.
  const std::string good = Triangle("ascii", {3, 0, 1, 2});
  const std::string head = good.substr(0, good.find("3 0 1 2"));
  struct Case {
    std::string bytes;
    std::vector<std::string> mentions;
  } cases[] = {
      {Triangle("ascii", {3, 0, 1, 7}), {"m.ply:14:", "face index 7 out of range", "3 vertices"}},
      {Triangle("ascii", {3, 0, -1, 2}), {"m.ply:14:", "face index -1"}},
      {Triangle("ascii", {2, 0, 7}), {"m.ply:14:", "face index 7 out of range"}},  // an edge's too
      {Triangle("ascii", {256, 0, 1, 2}), {"m.ply:14:", "out of range for its type"}},
      {head + "3 0 1 2 1\n", {"m.ply:14:", "more values", "for face 0"}},
      // One vertex line fewer than the header says: the face is read as the last vertex.
      {"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
       "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
       "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
       {"m.ply:13:", "for vertex 3", "fewer 'vertex' lines than its header says"}},
      {head + "3 0 1\n", {"m.ply:14:", "fewer values"}},
      {head + "3 0 1.5 2\n", {"m.ply:14:", "not an integer"}},
      {head + "3 0 1 2\n", {}},  // (the good file, to show the cases above differ by one thing)
      {Triangle("ascii", {3, 0, 1, 2}, std::numeric_limits<double>::quiet_NaN()),
       {"m.ply:12:", "nan"}},
      {Triangle("ascii", {3, 0, 1, 2}, std::numeric_limits<double>::infinity()),
       {"m.ply:12:", "inf"}},
      {Triangle("ascii", {3, 0, 1, 2}, 1e39), {"m.ply:12:", "float range"}},
      {Triangle("ascii", {3, 0, 1, 2}, 2e18), {"m.ply:12:", "beyond +-1e18"}},
      {Triangle("ascii", {3, 0, 1, 2}, 0, uint64_t{1'000'000'000'000}),
       {"m.ply:14:", "unexpected end of file in element 'face'"}},
      {good.substr(0, good.find("1 0 0") + 3), {"m.ply:12:", "fewer values"}},  // mid-vertex
      {good.substr(0, good.find("0 1 0") - 1), {"m.ply:12:", "unexpected end of file"}},
      {good.substr(0, good.size() - 4), {"m.ply:14:", "fewer values"}},  // mid-face
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n",
       {"m.ply:4:", "without end_header"}},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n-1.5\n",
       {"m.ply:5:", "'-1.5' (numbers: the data? the header needs an end_header line"}},
      {"ply\nformat ascii 2.0\nend_header\n", {"m.ply:2:", "version"}},
      {"ply\nformat binary_middle_endian 1.0\nend_header\n", {"m.ply:2:", "unsupported"}},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\n", {"m.ply:4:", "quad"}},
      {"ply\nformat ascii 1.0\nproperty float x\n", {"m.ply:3:", "before any element"}},
      {"ply\nformat ascii 1.0\nelement vertex -4\n", {"m.ply:3:", "element"}},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty float y\nend_header\n0\n",
       {"m.ply:5:", "x, y and z"}},
      {"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n"
       "element vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
       {"m.ply:9:", "face element before the vertex element is not supported"}},
      {"ply\nformat ascii 1.0\nelement vertex 1\nproperty list float int x\n",
       {"m.ply:4:", "integer"}},
      {"ply\nformat ascii 1.0\nmystery line\nend_header\n", {"m.ply:3:", "mystery"}},
      {"ply\nformat ascii 1.0\nelement vertex 1\x01\x02\nend_header\n", {"m.ply:3:", "binary"}},
      {"ply\n", {"m.ply:1:", "without end_header"}},
      // Cut inside a keyword (a persona read "unknown PLY header line 'elem'").
      {"ply\nformat ascii 1.0\nelem", {"m.ply:3:", "the file ends inside the PLY header, at 'elem' (truncated?)"}},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.bytes);
    Status status = ReadPlyText(files, c.bytes).status;
    if (c.mentions.empty()) EXPECT_TRUE(status.ok()) << status.message();
    else ExpectErrorMentions(status, c.mentions);
  }
}

// A normal or texture coordinate that is not a finite number (a scanner's NaN normal) stopped
// the whole conversion; it is optional data: its faces now go without it, and it is counted.
// A position that is not finite stays an error, naming the vertex and property.
TEST(PlyReader, ANonFiniteNormalOrUvIsDroppedAndAPositionNamesItsVertex) {
  ScratchFiles files;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::vector<TestPlyProperty> vertex = {{"float", "x", ""}, {"float", "y", ""},
                                               {"float", "z", ""}, {"float", "nx", ""},
                                               {"float", "ny", ""}, {"float", "nz", ""},
                                               {"float", "u", ""}, {"float", "v", ""}};
  for (const char* format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
    SCOPED_TRACE(format);
    const std::vector<TestPlyElement> model = {
        {"vertex", vertex,
         {{0, 0, 0, 0, 0, 1, 0, 0}, {1, 0, 0, nan, 0, 1, 1, 0}, {0, 1, 0, 0, 0, 1, 0, 1},
          {1, 1, 0, 0, 0, 1, 1, INFINITY}}},
        {"face", {{"int", "vertex_indices", "uchar"}}, {{3, 0, 1, 2}, {3, 0, 2, 3}}}};
    PlyResult r = ReadPlyText(files, TestPlyWriter::Build(format, model));
    ASSERT_TRUE(r.status.ok()) << r.status.message();
    EXPECT_EQ(r.info.attributes_not_finite, 2u);
    ASSERT_EQ(r.sink.triangles.size(), 2u);
    EXPECT_FALSE(r.sink.triangles[0].has_normals);  // vertex 1's normal
    EXPECT_TRUE(r.sink.triangles[0].has_uvs);
    EXPECT_TRUE(r.sink.triangles[1].has_normals);
    EXPECT_FALSE(r.sink.triangles[1].has_uvs);  // vertex 3's v
    std::vector<TestPlyElement> bad = model;
    bad[0].rows[2][1] = nan;
    ExpectErrorMentions(ReadPlyText(files, TestPlyWriter::Build(format, bad)).status,
                        {"m.ply", "(vertex 2, property 'y')"});
  }
}

// --shift in PLY: double coordinates (as scanners write them) shifted before they are floats.
TEST(PlyReader, AShiftKeepsDoubleCoordinatesFarFromTheOrigin) {
  ScratchFiles files;
  const std::vector<TestPlyProperty> xyz = {{"double", "x", ""}, {"double", "y", ""},
                                            {"double", "z", ""}};
  const std::vector<TestPlyElement> model = {
      {"vertex", xyz,
       {{500123.25, 5400456.5, 312}, {500123.28, 5400456.5, 312}, {500123.25, 5400456.53, 312}}},
      {"face", {{"int", "vertex_indices", "uchar"}}, {{3, 0, 1, 2}}}};
  for (const char* format : {"ascii", "binary_little_endian", "binary_big_endian"}) {
    SCOPED_TRACE(format);
    PositionShift automatic;
    automatic.automatic = true;
    PlyResult r;
    ReadOptions options;
    options.shift = &automatic;
    r.status = ReadFile(files.Write("m.ply", TestPlyWriter::Build(format, model)), &r.sink, &r.info,
                        options);
    ASSERT_TRUE(r.status.ok()) << r.status.message();
    ASSERT_EQ(r.sink.triangles.size(), 1u);
    EXPECT_NEAR(r.sink.triangles[0].p[1].x - r.sink.triangles[0].p[0].x, 0.03f, 1e-6f);
    EXPECT_NEAR(r.sink.triangles[0].p[2].y - r.sink.triangles[0].p[0].y, 0.03f, 1e-6f);
  }
}

TEST(PlyReader, BinaryErrorsNameFileAndByteOffset) {
  ScratchFiles files;
  for (const char* format : {"binary_little_endian", "binary_big_endian"}) {
    SCOPED_TRACE(format);
    const std::string good = Triangle(format, {3, 0, 1, 2});
    const size_t faces = 3 * 12;  // after three float x, y, z vertices
    struct Case {
      std::string bytes;
      size_t offset;  // from the start of the body
      std::string what;
    } cases[] = {
        {Triangle(format, {3, 0, 1, 9}), faces + 1 + 8, "face index 9 out of range"},
        {Triangle(format, {3, 0, 1, 9}, 0, std::nullopt, "uint"), faces + 9, "index 9"},
        {Triangle(format, {3, 0, 1, 9}, 0, std::nullopt, "short"), faces + 5, "index 9"},
        {Triangle(format, {2, 0, 9}), faces + 1 + 4, "face index 9 out of range"},
        {Triangle(format, {3, 0, 1, 2}, std::numeric_limits<double>::quiet_NaN()), 12 + 4,
         "not a finite float"},
        {Triangle(format, {3, 0, 1, 2}, 2e18), 12 + 8, "beyond +-1e18"},  // at its last value
        {Triangle(format, {3, 0, 1, 2}, 0, uint64_t{1'000'000'000'000}), faces + 13,
         "unexpected end of file"},
        {good.substr(0, BodyStart(good) + 20), 20, "unexpected end of file"},  // mid-vertex
        {good.substr(0, BodyStart(good) + faces + 6), faces + 5, "unexpected end of file"},
        {good.substr(0, BodyStart(good)), 0, "unexpected end of file"},
    };
    for (const Case& c : cases) {
      std::string where = "m.ply: byte " + std::to_string(BodyStart(c.bytes) + c.offset) + ":";
      ExpectErrorMentions(ReadPlyText(files, c.bytes).status, {where, c.what});
    }
  }
}

TEST(PlyReader, LargeFaceCountsAreCappedNotAllocated) {
  ScratchFiles files;
  TestPlyElement vertex{"vertex", {{"float", "x", ""}, {"float", "y", ""}, {"float", "z", ""}},
                        {{0, 0, 0}}};
  TestPlyElement face{"face", {{"int", "vertex_indices", "int"}}, {{2'000'000'000}}};
  std::string bytes = TestPlyWriter::Build("binary_little_endian", {vertex, face});
  ExpectErrorMentions(ReadPlyText(files, bytes).status,
                      {"m.ply: byte " + std::to_string(BodyStart(bytes) + 12) + ":",
                       "face with 2000000000 vertices"});
}

TEST(PlyReader, BinaryGarbageIsAnError) {
  ScratchFiles files;
  std::string garbage = Triangle("binary_little_endian", {3, 0, 1, 2});
  uint32_t state = 12345;
  for (size_t i = BodyStart(garbage); i < garbage.size(); ++i) {
    state = state * 1664525u + 1013904223u;
    garbage[i] = static_cast<char>(state >> 24);
  }
  Status status = ReadPlyText(files, garbage).status;
  ExpectErrorMentions(status, {"m.ply: byte "});
}

}  // namespace
}  // namespace raystack::import
