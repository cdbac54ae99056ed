#include "common/store/block_codec.h"

#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <string>
#include <vector>

namespace raystack::store {
namespace {

std::vector<uint8_t> FloatBytes(size_t n) {
  std::mt19937 rng(7);
  std::vector<float> f(n);
  float x = 1.0f;
  for (float& v : f) v = (x += 0.001f * static_cast<float>(rng() % 100));
  std::vector<uint8_t> bytes(n * 4);
  std::memcpy(bytes.data(), f.data(), bytes.size());
  return bytes;
}

TEST(BlockCodec, ShuffleRoundTripsAnySize) {
  for (size_t size : {0u, 1u, 3u, 4u, 5u, 64u, 1001u}) {
    std::vector<uint8_t> in(size), shuffled(size), out(size);
    for (size_t i = 0; i < size; ++i) in[i] = static_cast<uint8_t>(i * 37 + 11);
    ShuffleBytes(in.data(), size, shuffled.data());
    UnshuffleBytes(shuffled.data(), size, out.data());
    EXPECT_EQ(in, out) << size;
  }
}

TEST(BlockCodec, EncodeDecodeRoundTripsWithAndWithoutShuffle) {
  const std::vector<uint8_t> raw = FloatBytes(8192);
  for (bool shuffle : {true, false}) {
    std::vector<uint8_t> stored;
    EncodeBlock(raw, &stored, shuffle);
    AlignedBuffer scratch, out;
    ASSERT_TRUE(DecodeBlock(stored, static_cast<uint32_t>(raw.size()), shuffle, &scratch, &out).ok());
    EXPECT_EQ(0, std::memcmp(out.data(), raw.data(), raw.size()));
  }
}

TEST(BlockCodec, ShuffleCompressesSmoothFloatsBetter) {
  const std::vector<uint8_t> raw = FloatBytes(8192);
  std::vector<uint8_t> plain, shuffled;
  EncodeBlock(raw, &plain, false);
  EncodeBlock(raw, &shuffled, true);
  EXPECT_LT(shuffled.size(), plain.size());
}

TEST(BlockCodec, CorruptOrTruncatedDataIsAnErrorNotACrash) {
  const std::vector<uint8_t> raw = FloatBytes(4096);
  std::vector<uint8_t> stored;
  EncodeBlock(raw, &stored, true);
  AlignedBuffer scratch, out;
  const uint32_t size = static_cast<uint32_t>(raw.size());
  std::vector<uint8_t> cut(stored.begin(), stored.begin() + static_cast<long>(stored.size() / 2));
  EXPECT_FALSE(DecodeBlock(cut, size, true, &scratch, &out).ok());
  EXPECT_FALSE(DecodeBlock(stored, size + 4, true, &scratch, &out).ok());
  EXPECT_FALSE(DecodeBlock({}, size, true, &scratch, &out).ok());
  // Every single-byte change either fails to decode or decodes to the right size: never a crash.
  for (size_t i = 0; i < stored.size(); i += 7) {
    std::vector<uint8_t> bad = stored;
    bad[i] ^= 0x5a;
    Status s = DecodeBlock(bad, size, true, &scratch, &out);
    (void)s;
  }
}

// Fuzzer finding (tests/fuzz/corpus/block/regression-raw-size-0): a stored block of one
// zero byte claiming a raw size of 0 decodes "successfully" to nothing, and unshuffling
// nothing passed a null buffer to memcpy. A block is never empty: it is an error.
TEST(BlockCodec, ZeroRawSizeIsAnError) {
  AlignedBuffer scratch, out;
  const std::vector<uint8_t> one_zero{0};
  for (bool shuffle : {true, false}) {
    const Status s = DecodeBlock(one_zero, 0, shuffle, &scratch, &out);
    EXPECT_FALSE(s.ok());
    EXPECT_NE(s.message().find("raw size is 0"), std::string::npos) << s.message();
  }
}

TEST(BlockCodec, ChecksumSeesOneFlippedBit) {
  std::vector<uint8_t> bytes = FloatBytes(100);
  const uint64_t before = Checksum(bytes);
  bytes[17] ^= 1;
  EXPECT_NE(before, Checksum(bytes));
}

}  // namespace
}  // namespace raystack::store
