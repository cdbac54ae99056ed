// PopulatedArena (a block cache's decoded blocks): aligned pieces that never overlap, free room
// merged and reused, null when nothing fits, memory asked for only as the pieces reach it.

#include "common/base/populated_arena.h"
#include "tests/support/resident_pages.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <string>
#include <map>
#include <random>
#include <vector>

namespace raystack {
namespace {

constexpr uint64_t kMB = uint64_t{1} << 20;

TEST(PopulatedArena, PiecesAreAlignedInsideAndUsable) {
  PopulatedArena arena(4 * kMB);
  EXPECT_EQ(arena.capacity(), 4 * kMB);
  uint8_t* a = arena.Allocate(100);
  uint8_t* b = arena.Allocate(33 * 1024);
  ASSERT_NE(a, nullptr);
  ASSERT_NE(b, nullptr);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(a) % PopulatedArena::kAlignment, 0u);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(b) % PopulatedArena::kAlignment, 0u);
  EXPECT_TRUE(arena.Owns(a));
  EXPECT_TRUE(arena.Owns(b + 33 * 1024 - 1));
  EXPECT_GE(b, a + 128);  // 100 bytes take 128: the next piece starts after them
  std::memset(b, 0xab, 33 * 1024);
  std::memset(a, 0x11, 100);
  EXPECT_EQ(b[0], 0xab);
  EXPECT_EQ(arena.allocated_bytes(), 128u + 33 * 1024);
  arena.Free(a, 100);
  arena.Free(b, 33 * 1024);
  EXPECT_EQ(arena.allocated_bytes(), 0u);
}

TEST(PopulatedArena, NullWhenNothingFitsThenRoomAgainAfterFree) {
  PopulatedArena arena(2 * kMB);
  std::vector<uint8_t*> pieces;
  for (int i = 0; i < 16; ++i) pieces.push_back(arena.Allocate(128 * 1024));
  for (uint8_t* p : pieces) ASSERT_NE(p, nullptr);
  EXPECT_EQ(arena.Allocate(64), nullptr);  // exactly full
  arena.Free(pieces[5], 128 * 1024);
  EXPECT_EQ(arena.Allocate(128 * 1024 + 64), nullptr);  // one gap, too small
  EXPECT_EQ(arena.Allocate(128 * 1024), pieces[5]);     // reused where it was
}

TEST(PopulatedArena, FreedNeighboursMergeIntoOneLargerPiece) {
  PopulatedArena arena(2 * kMB);
  std::vector<uint8_t*> pieces;
  for (int i = 0; i < 16; ++i) pieces.push_back(arena.Allocate(128 * 1024));
  // Free 3, 5, then 4 between them: one gap of 384 KB, found whatever the order of frees.
  arena.Free(pieces[3], 128 * 1024);
  arena.Free(pieces[5], 128 * 1024);
  EXPECT_EQ(arena.Allocate(256 * 1024), nullptr);
  arena.Free(pieces[4], 128 * 1024);
  EXPECT_EQ(arena.Allocate(384 * 1024), pieces[3]);
}

TEST(PopulatedArena, BestFitLeavesLargeGapsForLargePieces) {
  PopulatedArena arena(2 * kMB);
  std::vector<uint8_t*> pieces;
  for (int i = 0; i < 16; ++i) pieces.push_back(arena.Allocate(128 * 1024));
  arena.Free(pieces[2], 128 * 1024);  // two gaps of 128 KB
  arena.Free(pieces[9], 128 * 1024);
  uint8_t* small = arena.Allocate(64 * 1024);
  ASSERT_EQ(small, pieces[2]);  // equal fits: the lower address
  arena.Free(small, 64 * 1024);
  uint8_t* a = arena.Allocate(100 * 1024);
  EXPECT_EQ(a, pieces[2]);
  uint8_t* b = arena.Allocate(20 * 1024);  // fits in a's remainder (28 KB): the tighter gap
  EXPECT_EQ(b, pieces[2] + 100 * 1024);
  EXPECT_NE(arena.Allocate(128 * 1024), nullptr);  // so the 128 KB gap at 9 is still whole
}

TEST(PopulatedArena, MemoryIsAskedForOnlyAsPiecesReachIt) {
  PopulatedArena arena(64 * kMB);
  EXPECT_EQ(arena.populated_bytes(), 0u);
  uint8_t* p = arena.Allocate(1000);
  EXPECT_EQ(arena.populated_bytes(), PopulatedArena::kStep);
  if (testing::KernelPopulatesOnRequest()) {  // in memory before the first write, one step only
    EXPECT_EQ(testing::ResidentShare(p, PopulatedArena::kStep), 1.0);
    EXPECT_EQ(testing::ResidentShare(p + PopulatedArena::kStep, PopulatedArena::kStep), 0.0);
  }
  std::vector<uint8_t*> more;
  for (int i = 0; i < 40; ++i) more.push_back(arena.Allocate(100 * 1024));  // ~4 MB in all
  EXPECT_EQ(arena.populated_bytes(), 2 * PopulatedArena::kStep);
  // Freed room at the top is used again before any new memory.
  for (uint8_t* q : more) arena.Free(q, 100 * 1024);
  for (int i = 0; i < 40; ++i) ASSERT_NE(arena.Allocate(100 * 1024), nullptr);
  EXPECT_EQ(arena.populated_bytes(), 2 * PopulatedArena::kStep);
  arena.Free(p, 1000);
}

// 4 KB pages, even where the kernel gives huge pages unasked: memory new to a VM's guest is
// mapped several times faster so (the top of populated_arena.h).
TEST(PopulatedArena, ItsMemoryIsAdvisedAsOrdinaryPages) {
  if (!std::filesystem::exists("/sys/kernel/mm/transparent_hugepage/enabled"))
    GTEST_SKIP() << "this kernel has no transparent huge pages";
  PopulatedArena arena(8 * kMB);
  uint8_t* p = arena.Allocate(1000);
  ASSERT_NE(p, nullptr);
  const std::string flags = testing::VmFlagsOf(p);
  ASSERT_FALSE(flags.empty()) << "no mapping in /proc/self/smaps holds the arena";
  EXPECT_NE(flags.find(" nh"), std::string::npos) << flags;
  EXPECT_EQ(flags.find(" hg"), std::string::npos) << flags;
  arena.Free(p, 1000);
}

// Address space the system cannot give (more than x86-64's 47 bits): a warning, no crash, and
// an arena without room, so its users take the heap.
TEST(PopulatedArena, AnArenaTheSystemRefusesHasNoRoom) {
  PopulatedArena arena(uint64_t{1} << 62);
  EXPECT_EQ(arena.capacity(), 0u);
  EXPECT_EQ(arena.Allocate(64), nullptr);
  EXPECT_EQ(arena.populated_bytes(), 0u);
}

// Random sizes allocated and freed in random order, against a model of which bytes are taken:
// no two live pieces overlap, each keeps the bytes written into it, and once everything is
// freed one piece of the whole capacity fits again (every gap merged back).
TEST(PopulatedArena, RandomUseNeverOverlapsAndMergesBackToWhole) {
  const uint64_t capacity = 8 * kMB;
  PopulatedArena arena(capacity);
  std::mt19937 rng(7);
  std::uniform_int_distribution<uint64_t> size_of(1, 130 * 1024);
  struct Piece {
    uint64_t bytes;
    uint8_t tag;
  };
  std::map<uint8_t*, Piece> live;
  for (int step = 0; step < 20000; ++step) {
    if (!live.empty() && (rng() % 2 == 0 || live.size() > 120)) {
      auto it = live.begin();
      std::advance(it, rng() % live.size());
      for (uint64_t i = 0; i < it->second.bytes; i += 997) ASSERT_EQ(it->first[i], it->second.tag);
      arena.Free(it->first, it->second.bytes);
      live.erase(it);
      continue;
    }
    const uint64_t bytes = size_of(rng);
    uint8_t* p = arena.Allocate(bytes);
    if (p == nullptr) continue;  // 120 pieces of up to 130 KB can exceed 8 MB
    ASSERT_TRUE(arena.Owns(p) && arena.Owns(p + bytes - 1));
    auto next = live.lower_bound(p);
    if (next != live.end()) {
      ASSERT_LE(p + bytes, next->first);
    }
    if (next != live.begin()) {
      auto prev = std::prev(next);
      ASSERT_LE(prev->first + prev->second.bytes, p);
    }
    const auto tag = static_cast<uint8_t>(step);
    std::memset(p, tag, bytes);
    live.emplace(p, Piece{bytes, tag});
  }
  EXPECT_GT(live.size(), 0u);
  for (const auto& [p, piece] : live) arena.Free(p, piece.bytes);
  EXPECT_EQ(arena.allocated_bytes(), 0u);
  EXPECT_NE(arena.Allocate(capacity), nullptr);
}

}  // namespace
}  // namespace raystack
