// The block cache remembers why a block failed, so every ray thread that asks for it later
// reports the first cause (naming the block), not a generic one, whichever reports first.

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace raystack::testing
