// The block cache remembers why a block failed, so every ray thread that asks for it later
// reports the first cause (naming the block), not a generic one, whichever reports first; its
// decoded blocks live in its huge-page arena, through evictions and reloads.

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <thread>
#include <vector>

#include "render_fixture.h"
#include "slave/block_cache.h"

namespace raystack::testing {
namespace {

TEST(BlockCache, AFailedBlockKeepsItsFirstCause) {
  TestStore s = BuildGenerated("sphere:4000", 4);
  ASSERT_GE(s.reader->blocks().size(), 2u);
  Expected<std::unique_ptr<slave::BlockCache>> cache =
      slave::BlockCache::Create(*s.reader, uint64_t{64} << 20);
  ASSERT_TRUE(cache.ok()) << cache.status().message();

  // A damaged block: the decode error names it.
  std::vector<uint8_t> stored;
  ASSERT_TRUE(s.reader->ReadStored(0, &stored).ok());
  stored[stored.size() / 2] ^= 0x5a;
  store::AlignedBuffer scratch;
  ASSERT_EQ((*cache)->BeginLoad(0), slave::BlockCache::Claim::kLoad);
  const Status decode = (*cache)->FinishLoad(0, stored, 0, &scratch);
  ASSERT_FALSE(decode.ok());
  EXPECT_EQ((*cache)->BeginLoad(0), slave::BlockCache::Claim::kFailed);
  EXPECT_EQ((*cache)->FailureOf(0).message(), decode.message());
  EXPECT_NE(decode.message().find("block 0"), std::string::npos) << decode.message();

  // A read that failed: the reader's error is kept as given.
  ASSERT_EQ((*cache)->BeginLoad(1), slave::BlockCache::Claim::kLoad);
  (*cache)->FailLoad(1, Status::Error("blocks.bin: block 1 at offset 42: read failed"));
  EXPECT_EQ((*cache)->BeginLoad(1), slave::BlockCache::Claim::kFailed);
  EXPECT_EQ((*cache)->FailureOf(1).message(), "blocks.bin: block 1 at offset 42: read failed");
  EXPECT_EQ((*cache)->used_bytes(), 0u);  // both reservations were given back
}

// Loads every block of a store, a few times over, into a budget of a few blocks: the blocks
// decode into the arena (the C heap only when no gap fits), their views read correctly from
// it, and the arena never holds more than the resident blocks.
uint64_t LoadEveryBlock(slave::BlockCache* cache, const store::StoreReader& reader, int rounds) {
  std::vector<uint8_t> stored;
  store::AlignedBuffer scratch;
  uint64_t in_arena = 0;
  for (int round = 0; round < rounds; ++round) {
    for (uint32_t id = 0; id < reader.blocks().size(); ++id) {
      if (cache->BeginLoad(id) != slave::BlockCache::Claim::kLoad) continue;  // still resident
      EXPECT_TRUE(reader.ReadStored(id, &stored).ok());
      EXPECT_TRUE(cache->FinishLoad(id, stored, 1, &scratch).ok());
      const store::BlockView* view = cache->TryAcquire(id);
      EXPECT_NE(view, nullptr);
      if (view == nullptr) return 0;
      EXPECT_EQ(view->triangle_count(), reader.blocks()[id].triangle_count);
      cache->Release(id);
      cache->Release(id);  // FinishLoad's pin
      EXPECT_LE(cache->arena_bytes(), cache->used_bytes());
      in_arena += cache->arena_bytes();
    }
  }
  return in_arena;
}

TEST(BlockCache, BlocksDecodeIntoItsArena) {
  TestStore s = BuildGenerated("sphere:20000", 4);
  const auto& blocks = s.reader->blocks();
  ASSERT_GE(blocks.size(), 8u);
  uint64_t total = 0;
  for (const store::BlockEntry& e : blocks) total += (uint64_t{e.raw_bytes} + 63) & ~uint64_t{63};

  // Room for everything: one arena of the store's size, and every block in it.
  auto roomy = slave::BlockCache::Create(*s.reader, total * 2);
  ASSERT_TRUE(roomy.ok());
  EXPECT_GE((*roomy)->arena_capacity(), total);
  LoadEveryBlock(roomy->get(), *s.reader, 1);
  EXPECT_EQ((*roomy)->arena_bytes(), total);
  EXPECT_EQ((*roomy)->used_bytes(), total);

  // A budget of about a quarter of the store: evictions and reloads, blocks still in the arena.
  auto tight = slave::BlockCache::Create(*s.reader, total / 4);
  ASSERT_TRUE(tight.ok());
  const uint64_t in_arena = LoadEveryBlock(tight->get(), *s.reader, 3);
  EXPECT_GT((*tight)->evictions(), 0u);
  EXPECT_GT(in_arena, 0u);
  EXPECT_LE((*tight)->arena_bytes(), (*tight)->used_bytes());
}

// An unlimited cache (incore and bvh modes) never evicts, so a resident block's view is handed
// out without a pin: the one TryAcquire gives, null before the block is loaded. A bounded cache
// refuses (it may evict the block under the caller).
TEST(BlockCache, AnUnlimitedCacheHandsOutResidentViewsWithoutAPin) {
  TestStore s = BuildGenerated("sphere:4000", 4);
  ASSERT_GE(s.reader->blocks().size(), 2u);
  auto cache = slave::BlockCache::Create(*s.reader, slave::BlockCache::kUnlimited);
  ASSERT_TRUE(cache.ok());
  EXPECT_EQ((*cache)->ResidentView(0), nullptr);
  std::vector<uint8_t> stored;
  store::AlignedBuffer scratch;
  ASSERT_EQ((*cache)->BeginLoad(0), slave::BlockCache::Claim::kLoad);
  ASSERT_TRUE(s.reader->ReadStored(0, &stored).ok());
  ASSERT_TRUE((*cache)->FinishLoad(0, stored, 0, &scratch).ok());
  const store::BlockView* pinned = (*cache)->TryAcquire(0);
  ASSERT_NE(pinned, nullptr);
  (*cache)->Release(0);
  EXPECT_EQ((*cache)->ResidentView(0), pinned);
  EXPECT_EQ((*cache)->ResidentView(0)->triangle_count(), s.reader->blocks()[0].triangle_count);
  EXPECT_EQ((*cache)->ResidentView(1), nullptr);

  auto bounded = slave::BlockCache::Create(*s.reader, uint64_t{64} << 20);
  ASSERT_TRUE(bounded.ok());
  EXPECT_DEATH((*bounded)->ResidentView(0), "budget_ == kUnlimited");
}

// Two sync ray threads miss one block while the cache is full of pinned blocks: both wait for
// room. Once there is room the block is loaded once; the other thread finds it loading or
// resident. It was claimed twice: the second load freed the first one's data under its pin
// and charged the budget twice (found by ThreadSanitizer in --mode sync).
TEST(BlockCache, TwoThreadsWaitingForRoomForOneBlockLoadItOnce) {
  TestStore s = BuildGenerated("spheres:60000");
  const auto& blocks = s.reader->blocks();
  ASSERT_GE(blocks.size(), 3u);
  std::vector<uint32_t> ids(blocks.size());
  for (uint32_t i = 0; i < ids.size(); ++i) ids[i] = i;
  const auto charge = [&](uint32_t id) {
    return (uint64_t{blocks[id].raw_bytes} + 63) & ~uint64_t{63};
  };
  std::sort(ids.begin(), ids.end(), [&](uint32_t a, uint32_t b) { return charge(a) > charge(b); });
  const uint32_t big = ids[0], other = ids[1], wanted = ids.back();
  Expected<std::unique_ptr<slave::BlockCache>> made =
      slave::BlockCache::Create(*s.reader, charge(big) + charge(other));
  ASSERT_TRUE(made.ok()) << made.status().message();
  slave::BlockCache& cache = **made;
  std::vector<uint8_t> stored;
  store::AlignedBuffer scratch;
  for (const uint32_t id : {big, other}) {  // resident and pinned: the cache is full
    ASSERT_EQ(cache.BeginLoad(id), slave::BlockCache::Claim::kLoad);
    ASSERT_TRUE(s.reader->ReadStored(id, &stored).ok());
    ASSERT_TRUE(cache.FinishLoad(id, stored, 1, &scratch).ok());
  }
  std::atomic<int> loads{0}, waiting{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 2; ++t)
    threads.emplace_back([&] {
      ++waiting;
      if (cache.BeginLoad(wanted) != slave::BlockCache::Claim::kLoad) return;
      ++loads;
      std::vector<uint8_t> bytes;
      store::AlignedBuffer buffer;
      EXPECT_TRUE(s.reader->ReadStored(wanted, &bytes).ok());
      EXPECT_TRUE(cache.FinishLoad(wanted, bytes, 0, &buffer).ok());
    });
  while (waiting.load() < 2) std::this_thread::yield();
  std::this_thread::sleep_for(std::chrono::milliseconds(50));  // both inside BeginLoad, waiting
  cache.Release(big);
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(loads.load(), 1) << "block " << wanted << " was claimed for loading twice";
  EXPECT_EQ(cache.resident_count(), 2u);
  EXPECT_LE(cache.used_bytes(), cache.budget());
  EXPECT_EQ(cache.used_bytes(), charge(other) + charge(wanted));
}

}  // namespace
}  // namespace raystack::testing
