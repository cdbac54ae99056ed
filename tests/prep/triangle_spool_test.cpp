// A spool gives back exactly what was appended, in order, whether it stayed in memory or
// spilled to disk, and it cleans up after itself.

#include "tools/prep/triangle_spool.h"

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <unistd.h>

#include <csignal>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <vector>

#include "common/base/temp_dir.h"
#include "tools/prep/write_behind.h"
#include "tests/support/test_dir.h"

namespace raystack::prep {
namespace {

// Triangle i; every third has normals and uvs, every fifth only uvs (none when `plain`).
PackedTriangle MakeTriangle(uint32_t i, TriangleAttributes* a, bool plain = false) {
  PackedTriangle t;
  const float f = static_cast<float>(i);
  t.p[0] = {f, f + 0.5f, -f};
  t.p[1] = {f + 1, f * 2, 3};
  t.p[2] = {-f, 7, f * 0.25f};
  t.id = i * 7 + 3;
  t.material_and_flags = i % 11;
  *a = TriangleAttributes{};
  if (i % 3 == 0 && !plain)
    t.material_and_flags |= PackedTriangle::kHasNormals | PackedTriangle::kHasUvs;
  if (i % 5 == 0 && !plain) t.material_and_flags |= PackedTriangle::kHasUvs;
  if (t.has_normals() || t.has_uvs()) {
    for (int c = 0; c < 3; ++c) {
      a->n[c] = {f * 0.1f + static_cast<float>(c), 1, 2};
      a->uv[c][0] = f * 0.01f;
      a->uv[c][1] = static_cast<float>(c) - f;
    }
  }
  return t;
}

bool SameTriangle(const PackedTriangle& a, const PackedTriangle& b) {
  return std::memcmp(&a, &b, sizeof a) == 0;
}

bool SameAttributes(const TriangleAttributes& a, const TriangleAttributes& b) {
  return std::memcmp(&a, &b, sizeof a) == 0;
}

class TriangleSpoolTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = raystack::testing::MakeTestDir();
    ASSERT_TRUE(dir_);
  }

  static void Fill(TriangleSpool* spool, uint32_t n, bool plain = false) {
    for (uint32_t i = 0; i < n; ++i) {
      TriangleAttributes a;
      const PackedTriangle t = MakeTriangle(i, &a, plain);
      ASSERT_TRUE(spool->Append(t, &a).ok());
    }
    ASSERT_TRUE(spool->Close().ok());
  }

  // Reads the spool back and checks it holds triangles 0..n-1 in order.
  static void ExpectHolds(const TriangleSpool& spool, uint32_t n, bool plain = false) {
    EXPECT_EQ(spool.triangles(), n);
    uint32_t next = 0;
    int batches = 0;
    Status s = spool.ForEach([&](std::span<const PackedTriangle> tris,
                                 std::span<const TriangleAttributes> attrs) {
      ++batches;
      EXPECT_EQ(attrs.size(), plain ? 0 : tris.size());
      for (size_t k = 0; k < tris.size(); ++k, ++next) {
        TriangleAttributes expected_attributes;
        const PackedTriangle expected = MakeTriangle(next, &expected_attributes, plain);
        if (!SameTriangle(tris[k], expected)) {
          ADD_FAILURE() << "triangle " << next << " differs";
          return Status::Error("stop");
        }
        if ((expected.has_normals() || expected.has_uvs()) &&
            !SameAttributes(attrs[k], expected_attributes)) {
          ADD_FAILURE() << "attributes of triangle " << next << " differ";
          return Status::Error("stop");
        }
      }
      return OkStatus();
    });
    EXPECT_TRUE(s.ok()) << s.message();
    EXPECT_EQ(next, n);
    EXPECT_GT(batches, 0);
  }

  std::unique_ptr<TempDir> dir_;
};

// Enough triangles for several visitor batches and several 1 MB read buffers when spilled.
constexpr uint32_t kTriangles = 30000;

TEST_F(TriangleSpoolTest, InMemoryGivesBackEveryTriangleInOrder) {
  TriangleSpool spool(dir_->File("memory.tmp"), uint64_t{1} << 30);
  Fill(&spool, kTriangles);
  EXPECT_FALSE(spool.spilled());
  EXPECT_FALSE(std::filesystem::exists(dir_->File("memory.tmp")));
  ExpectHolds(spool, kTriangles);
}

TEST_F(TriangleSpoolTest, SpilledGivesBackEveryTriangleInOrder) {
  // A budget of a few triangles: the first ones are in memory when it spills.
  TriangleSpool spool(dir_->File("spilled.tmp"), 500, 4096);
  Fill(&spool, kTriangles);
  EXPECT_TRUE(spool.spilled());
  EXPECT_TRUE(std::filesystem::exists(dir_->File("spilled.tmp")));
  ExpectHolds(spool, kTriangles);
  ExpectHolds(spool, kTriangles);  // readable more than once
}

TEST_F(TriangleSpoolTest, SpilledAndInMemoryAgreeOnBytes) {
  TriangleSpool memory(dir_->File("a.tmp"), uint64_t{1} << 30);
  TriangleSpool spilled(dir_->File("b.tmp"), 0);
  Fill(&memory, 1000);
  Fill(&spilled, 1000);
  EXPECT_EQ(memory.bytes(), spilled.bytes());
  // 44 bytes per triangle, plus 60 for each of the 334 + 200 - 67 with attributes.
  EXPECT_EQ(spilled.bytes(), 1000u * 44 + (334u + 200 - 67) * 60);
  EXPECT_EQ(std::filesystem::file_size(dir_->File("b.tmp")), spilled.bytes());
}

TEST_F(TriangleSpoolTest, MovedSpoolKeepsItsTriangles) {
  TriangleSpool spool(dir_->File("moved.tmp"), 0);
  Fill(&spool, 2000);
  TriangleSpool moved(std::move(spool));
  ExpectHolds(moved, 2000);
}

TEST_F(TriangleSpoolTest, ClearRemovesTheSpillFile) {
  const std::string path = dir_->File("cleared.tmp");
  TriangleSpool spool(path, 0);
  Fill(&spool, 100);
  ASSERT_TRUE(std::filesystem::exists(path));
  spool.Clear();
  EXPECT_FALSE(std::filesystem::exists(path));
  EXPECT_EQ(spool.triangles(), 0u);
  EXPECT_EQ(spool.bytes(), 0u);
}

TEST_F(TriangleSpoolTest, DestructorRemovesTheSpillFile) {
  const std::string path = dir_->File("destroyed.tmp");
  {
    TriangleSpool spool(path, 0);
    Fill(&spool, 100);
    ASSERT_TRUE(std::filesystem::exists(path));
  }
  EXPECT_FALSE(std::filesystem::exists(path));
}

// Without attributes, records are read back a batch at a time rather than one by one.
TEST_F(TriangleSpoolTest, WithoutAttributesGivesBackEveryTriangleInOrder) {
  TriangleSpool memory(dir_->File("plain-memory.tmp"), uint64_t{1} << 30);
  TriangleSpool spilled(dir_->File("plain-spilled.tmp"), 500, 4096);
  Fill(&memory, kTriangles, /*plain=*/true);
  Fill(&spilled, kTriangles, /*plain=*/true);
  EXPECT_TRUE(spilled.spilled());
  EXPECT_EQ(spilled.bytes(), uint64_t{kTriangles} * sizeof(PackedTriangle));
  ExpectHolds(memory, kTriangles, /*plain=*/true);
  ExpectHolds(spilled, kTriangles, /*plain=*/true);
}

TEST_F(TriangleSpoolTest, TruncatedFileWithoutAttributesIsDamaged) {
  const std::string path = dir_->File("truncated.tmp");
  TriangleSpool spool(path, 0);
  Fill(&spool, 100, /*plain=*/true);
  std::filesystem::resize_file(path, 99 * sizeof(PackedTriangle) + 10);
  Status s = spool.ForEach([](auto, auto) { return OkStatus(); });
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("damaged"), std::string::npos) << s.message();
}

// Pieces read by range, one after the other, are the whole spool (the partition pass reads
// pieces on several threads), in memory and spilled; a range needs same-size records.
TEST_F(TriangleSpoolTest, RangesInTurnGiveBackEveryTriangleInOrder) {
  TriangleSpool memory(dir_->File("range-memory.tmp"), uint64_t{1} << 30);
  TriangleSpool spilled(dir_->File("range-spilled.tmp"), 500, 4096);
  Fill(&memory, kTriangles, /*plain=*/true);
  Fill(&spilled, kTriangles, /*plain=*/true);
  for (const TriangleSpool* spool : {&memory, &spilled}) {
    uint32_t next = 0;
    const uint64_t cuts[] = {0, 1, 9000, 9001, 25000, kTriangles};
    for (size_t c = 0; c + 1 < std::size(cuts); ++c) {
      Status s = spool->ForEachRange(cuts[c], cuts[c + 1] - cuts[c],
                                     [&](std::span<const PackedTriangle> tris, auto attrs) {
                                       EXPECT_TRUE(attrs.empty());
                                       for (const PackedTriangle& t : tris) {
                                         TriangleAttributes a;
                                         if (!SameTriangle(t, MakeTriangle(next++, &a, true)))
                                           return Status::Error("triangle differs");
                                       }
                                       return OkStatus();
                                     });
      EXPECT_TRUE(s.ok()) << s.message();
      EXPECT_EQ(next, cuts[c + 1]);
    }
    Status beyond = spool->ForEachRange(kTriangles - 5, 6, [](auto, auto) { return OkStatus(); });
    ASSERT_FALSE(beyond.ok());
    EXPECT_NE(beyond.message().find("beyond"), std::string::npos) << beyond.message();
  }
  TriangleSpool mixed(dir_->File("range-mixed.tmp"), 0);
  Fill(&mixed, 100);
  Status s = mixed.ForEachRange(0, 10, [](auto, auto) { return OkStatus(); });
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("range-mixed.tmp"), std::string::npos) << s.message();
}

// Spools sharing one writer thread, appended to in turn (as partition buckets are), each get
// back exactly their own triangles, with and without attributes.
TEST_F(TriangleSpoolTest, ThroughWriteBehindGivesBackEveryTriangleInOrder) {
  WriteBehind writer(1000, 3);  // small buffers and queue: many hand-overs and waits
  std::vector<TriangleSpool> spools;
  for (int k = 0; k < 4; ++k)
    spools.emplace_back(dir_->File("behind-" + std::to_string(k) + ".tmp"), writer);
  for (uint32_t i = 0; i < kTriangles; ++i)
    for (int k = 0; k < 4; ++k) {
      TriangleAttributes a;
      const PackedTriangle t = MakeTriangle(i, &a, /*plain=*/k % 2 == 0);
      ASSERT_TRUE(spools[k].Append(t, &a).ok());
    }
  for (TriangleSpool& spool : spools) ASSERT_TRUE(spool.Close().ok());
  for (int k = 0; k < 4; ++k) {
    EXPECT_TRUE(spools[k].spilled());
    EXPECT_EQ(std::filesystem::file_size(dir_->File("behind-" + std::to_string(k) + ".tmp")),
              spools[k].bytes());
    ExpectHolds(spools[k], kTriangles, /*plain=*/k % 2 == 0);
  }
}

TEST_F(TriangleSpoolTest, ThroughWriteBehindUnwritablePathIsAnErrorNamingIt) {
  const std::string file = dir_->File("plain-file");
  std::ofstream(file) << "not a directory";
  const std::string path = file + "/spill.tmp";
  WriteBehind writer(4096, 2);
  TriangleSpool spool(path, writer);
  TriangleAttributes a;
  const PackedTriangle t = MakeTriangle(1, &a);
  Status s = spool.Append(t, &a);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find(path), std::string::npos) << s.message();
}

// A full disk stops the appends within a few buffers, not at Close after the whole pass (a
// user's temp folder filled in seconds, and the partition pass went on for minutes). A file size
// limit stands in for the full disk (SIGXFSZ ignored, a write past it fails with EFBIG as on
// ENOSPC); lowered for this test only, and put back.
TEST_F(TriangleSpoolTest, ThroughWriteBehindAFullDiskStopsTheAppendsAtOnce) {
  rlimit before{};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &before), 0);
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);
  rlimit small = before;
  small.rlim_cur = 64 << 10;
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &small), 0);
  Status s = OkStatus();
  uint32_t appended = 0, per_buffer = 0;
  {
    WriteBehind writer(4096, 2);
    TriangleSpool spool(dir_->File("full.tmp"), writer);
    TriangleAttributes a;
    const PackedTriangle t = MakeTriangle(1, &a, /*plain=*/true);
    per_buffer = 4096 / sizeof t;
    const uint32_t limit = (64 << 10) / sizeof t;  // triangles that fit under the limit
    for (; appended < 1000 * per_buffer && s.ok(); ++appended) s = spool.Append(t, &a);
    EXPECT_LT(appended, limit + 10 * per_buffer) << "the error came only after " << appended << " triangles";
  }
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &before), 0);
  std::signal(SIGXFSZ, old_handler);
  ASSERT_FALSE(s.ok()) << "every append of 1000 buffers' worth succeeded";
  EXPECT_NE(s.message().find("full.tmp: write failed (disk full?)"), std::string::npos) << s.message();
}

TEST_F(TriangleSpoolTest, UnwritablePathIsAnErrorNamingIt) {
  // A path below a regular file cannot be created, even by root.
  const std::string file = dir_->File("plain-file");
  std::ofstream(file) << "not a directory";
  const std::string path = file + "/spill.tmp";
  TriangleSpool spool(path, 0);
  TriangleAttributes a;
  const PackedTriangle t = MakeTriangle(1, &a);
  Status s = spool.Append(t, &a);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find(path), std::string::npos) << s.message();
}

}  // namespace
}  // namespace raystack::prep
