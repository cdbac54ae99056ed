// Messages between ranks: every type round-trips; a malformed or hostile message (truncated,
// foreign, another protocol version, a wrong size, a huge count, a forged sender) is an error
// naming the sender, never a crash or a misread.

#include <gtest/gtest.h>

#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "common/wire/message.h"

namespace raystack::wire {
namespace {

render::SampleResult Sample(uint32_t i) {
  render::SampleResult s{};
  s.pixel = i * 7;
  s.sample = i % 3;
  s.rgb[0] = 0.5f * static_cast<float>(i);
  s.rgb[1] = -0.0f;
  s.rgb[2] = std::numeric_limits<float>::quiet_NaN();  // (counted by the film, never merged)
  s.z = static_cast<float>(i) + 0.25f;
  s.normal[1] = 1.0f / static_cast<float>(i + 1);
  s.albedo[2] = 0.125f * static_cast<float>(i);
  s.hit = i & 1;
  return s;
}

// What the master reads of a sample: everything for sample 0, no primary layers otherwise.
render::SampleResult AsReceived(render::SampleResult s) {
  if (s.sample != 0) {
    s.z = std::numeric_limits<float>::infinity();
    for (int c = 0; c < 3; ++c) s.normal[c] = s.albedo[c] = 0.0f;
  }
  return s;
}

TEST(Message, EveryTypeRoundTrips) {
  {
    const std::vector<uint8_t> bytes1 = Encode(3, TileRequest{2, 1});
    const Expected<Message> m = Decode(bytes1, 3);
    ASSERT_TRUE(m.ok()) << m.status().message();
    EXPECT_EQ(m->type(), MessageType::kTileRequest);
    EXPECT_EQ(m->tile_request().frame, 2u);
    EXPECT_EQ(m->tile_request().thread, 1u);
  }
  {
    const std::vector<uint8_t> bytes = Encode(0, TileAssign{1, 2, 32, 64, 48, 96, 0, 4, 8, 16, 64});
    const Expected<Message> m = Decode(bytes, 0);
    ASSERT_TRUE(m.ok()) << m.status().message();
    const TileAssign t = m->tile_assign();
    EXPECT_EQ(t.x0, 32);
    EXPECT_EQ(t.y1, 96);
    EXPECT_EQ(t.none, 0u);
    EXPECT_EQ(t.sample_begin, 4u);
    EXPECT_EQ(t.sample_end, 8u);
    EXPECT_EQ(t.rank_begin, 16u);
    EXPECT_EQ(t.rank_end, 64u);
  }
  {
    FrameDone done{};
    done.frame = 4;
    done.samples = 123456789012ull;
    done.seconds = 1.5;
    done.process_cpu_seconds = 0.25;
    done.flags = kFrameDoneDirectReads;
    done.tile_wait_seconds = 0.125;
    done.block_wait_seconds = 0.0625;
    done.engine_seconds = 1.75;
    const std::vector<uint8_t> bytes2 = Encode(5, done);
    const Expected<Message> m = Decode(bytes2, 5);
    ASSERT_TRUE(m.ok());
    EXPECT_EQ(m->frame_done().samples, 123456789012ull);
    EXPECT_EQ(m->frame_done().seconds, 1.5);
    EXPECT_EQ(m->frame_done().process_cpu_seconds, 0.25);
    EXPECT_EQ(m->frame_done().flags, kFrameDoneDirectReads);
    EXPECT_EQ(m->frame_done().tile_wait_seconds, 0.125);
    EXPECT_EQ(m->frame_done().block_wait_seconds, 0.0625);
    EXPECT_EQ(m->frame_done().engine_seconds, 1.75);
  }
  {
    const std::vector<uint8_t> bytes3 = EncodeError(2, "block 7: damaged\x1b[2J");
    const Expected<Message> m = Decode(bytes3, 2);
    ASSERT_TRUE(m.ok());
    EXPECT_EQ(m->error_text(), "block 7: damaged?[2J");  // control characters neutralised
    EXPECT_EQ(EncodeError(2, std::string(100000, 'x')).size(),
              sizeof(MessageHeader) + kMaxErrorText);
  }
  {
    Hello hello{8, kHelloRemoteBlocks, 0x1234, 0x5678, {}, {}};
    SetHelloText(hello.build, "0.1.0 (" + std::string(60, 'c') + ")");  // cut to 39 bytes
    SetHelloText(hello.host, "node7");
    const std::vector<uint8_t> bytes4 = Encode(1, hello);
    const Expected<Message> m = Decode(bytes4, 1);
    ASSERT_TRUE(m.ok());
    const Hello got = m->hello();
    EXPECT_EQ(got.ray_threads, 8u);
    EXPECT_EQ(got.flags, kHelloRemoteBlocks);
    EXPECT_EQ(got.store_checksum, 0x1234u);
    EXPECT_EQ(got.scene_checksum, 0x5678u);
    EXPECT_EQ(HelloText(got.build), "0.1.0 (" + std::string(32, 'c'));
    EXPECT_EQ(HelloText(got.host), "node7");
    // A sender's bytes: no terminating nul, control characters.
    Hello hostile{};
    std::memset(hostile.host, '\x1b', sizeof hostile.host);
    EXPECT_EQ(HelloText(hostile.host), std::string(40, '?'));
  }
  const std::vector<uint8_t> bytes5 = Encode(0, Shutdown{0, 0});
  ASSERT_TRUE(Decode(bytes5, 0).ok());
  {
    const std::vector<uint8_t> bytes6 = Encode(3, Heartbeat{17, 0});
    const Expected<Message> m = Decode(bytes6, 3);
    ASSERT_TRUE(m.ok());
    EXPECT_EQ(m->type(), MessageType::kHeartbeat);
    EXPECT_EQ(m->heartbeat().sequence, 17u);
  }
  {
    const std::vector<uint8_t> bytes7 = Encode(0, RankLost{2, 0});
    const Expected<Message> m = Decode(bytes7, 0);
    ASSERT_TRUE(m.ok());
    EXPECT_EQ(m->rank_lost().rank, 2u);
  }
}

TEST(Message, PixelBatchRoundTripsBitForBit) {
  std::vector<render::SampleResult> samples;
  for (uint32_t i = 0; i < 1000; ++i) samples.push_back(Sample(i));
  const std::vector<uint8_t> bytes = EncodePixelBatch(2, 7, samples, 98765);
  const Expected<Message> m = Decode(bytes, 2);
  ASSERT_TRUE(m.ok()) << m.status().message();
  EXPECT_EQ(m->batch_header().frame, 7u);
  EXPECT_EQ(m->batch_header().rays, 98765u);
  std::vector<render::SampleResult> got;
  m->batch_samples(&got);
  // Sample 0 first, then the others, each in the batch's order; the primary layers only for
  // sample 0, which is all the film keeps of them.
  std::vector<render::SampleResult> expected;
  for (int pass = 0; pass < 2; ++pass)
    for (const render::SampleResult& s : samples)
      if ((s.sample == 0) == (pass == 0)) expected.push_back(AsReceived(s));
  ASSERT_EQ(got.size(), expected.size());
  EXPECT_EQ(std::memcmp(got.data(), expected.data(), expected.size() * sizeof expected[0]), 0);
  EXPECT_EQ(m->batch_header().primary, 334u);  // i % 3 == 0 for 334 of 1000
  // 20 bytes a sample, 28 more for sample 0: a third of the 52 of the whole record.
  EXPECT_EQ(bytes.size(), sizeof(MessageHeader) + sizeof(PixelBatchHeader) + 1000 * 20 + 334 * 28);
  // An empty batch is valid too.
  const std::vector<uint8_t> bytes8 = EncodePixelBatch(2, 7, {});
  ASSERT_TRUE(Decode(bytes8, 2).ok());
}

void ExpectError(const std::vector<uint8_t>& bytes, int from, const std::string& part) {
  const Expected<Message> m = Decode(bytes, from);
  ASSERT_FALSE(m.ok()) << "accepted: " << part;
  EXPECT_NE(m.status().message().find("rank " + std::to_string(from)), std::string::npos)
      << m.status().message();
  EXPECT_NE(m.status().message().find(part), std::string::npos) << m.status().message();
}

template <typename T>
void Poke(std::vector<uint8_t>* bytes, size_t offset, T value) {
  std::memcpy(bytes->data() + offset, &value, sizeof value);
}

TEST(Message, MalformedMessagesNameTheSender) {
  const std::vector<uint8_t> good = Encode(4, TileRequest{0, 0});
  ExpectError({}, 4, "shorter than a message header");
  ExpectError(std::vector<uint8_t>(good.begin(), good.begin() + 10), 4, "shorter");
  std::vector<uint8_t> b = good;
  Poke<uint32_t>(&b, 0, 0xdeadbeef);
  ExpectError(b, 4, "not a raystack message");
  b = good;
  Poke<uint16_t>(&b, 4, kProtocolVersion + 1);
  ExpectError(b, 4, "protocol version " + std::to_string(kProtocolVersion + 1));
  b = good;
  Poke<uint16_t>(&b, 6, 99);
  ExpectError(b, 4, "unknown type 99");
  b = good;
  Poke<uint16_t>(&b, 6, 0);
  ExpectError(b, 4, "unknown type 0");
  ExpectError(good, 3, "claims to come from rank 4");  // forged sender
  b = good;
  b.push_back(0);
  ExpectError(b, 4, "payload bytes");
  b = good;
  Poke<uint32_t>(&b, 12, 0xffffffffu);  // a size that would be a huge allocation
  ExpectError(b, 4, "payload bytes");
  // A fixed-size message with a consistent but wrong payload size.
  b = Encode(4, TileAssign{});
  b.resize(b.size() - 4);
  Poke<uint32_t>(&b, 12, static_cast<uint32_t>(b.size() - sizeof(MessageHeader)));
  ExpectError(b, 4, "expected 40");
}

TEST(Message, HostilePixelBatchesAreRefused) {
  std::vector<render::SampleResult> samples(10, Sample(1));
  std::vector<uint8_t> b = EncodePixelBatch(1, 0, samples);
  Poke<uint32_t>(&b, sizeof(MessageHeader) + 4, 0xffffffffu);  // count
  ExpectError(b, 1, "samples (at most");
  b = EncodePixelBatch(1, 0, samples);
  Poke<uint32_t>(&b, sizeof(MessageHeader) + 4, 11);  // one more than sent
  ExpectError(b, 1, "pixel batch of 11 samples (0 sample 0) in");
  b = EncodePixelBatch(1, 0, samples);
  Poke<uint32_t>(&b, sizeof(MessageHeader) + 16, 11);  // more sample 0s than samples
  ExpectError(b, 1, "10 samples, 11 of them sample 0");
  // Primary layers that do not belong to the first samples, or a sample 0 without them.
  samples = {Sample(0), Sample(1), Sample(3)};  // samples 0, 1, 0
  b = EncodePixelBatch(1, 0, samples);
  const size_t records = sizeof(MessageHeader) + sizeof(PixelBatchHeader);
  std::vector<uint8_t> swapped = b;  // record 1 (a sample 0) and record 2 (sample 1) swapped
  std::memcpy(swapped.data() + records + 20, b.data() + records + 40, 20);
  std::memcpy(swapped.data() + records + 40, b.data() + records + 20, 20);
  ExpectError(swapped, 1, "its sample 1 (pixel 7, sample 1) should be a sample 0");
  Poke<uint32_t>(&b, records + 2 * 20 + 4, 0);  // the last sample becomes a sample 0
  ExpectError(b, 1, "its sample 2 (pixel 7, sample 0) is a sample 0 without its primary");
  b = EncodePixelBatch(1, 0, samples);
  b.resize(sizeof(MessageHeader) + 4);
  Poke<uint32_t>(&b, 12, 4);
  ExpectError(b, 1, "without its count");
}

// A block request carries several runs (the fetches that queued for one owner); its answer
// says how many runs it answers.
TEST(Message, BlockRequestsCarryTheirRuns) {
  const std::vector<BlockRun> runs = {{10, 2}, {40, 1}, {7, 3}};
  const std::vector<uint8_t> bytes = EncodeBlockRequest(3, 42, runs);
  const Expected<Message> m = Decode(bytes, 3);
  ASSERT_TRUE(m.ok()) << m.status().message();
  EXPECT_EQ(m->block_request().request, 42u);
  EXPECT_EQ(m->block_request().runs, 3u);
  std::vector<BlockRun> got;
  m->block_runs(&got);
  ASSERT_EQ(got.size(), runs.size());
  for (size_t i = 0; i < runs.size(); ++i) {
    EXPECT_EQ(got[i].first, runs[i].first);
    EXPECT_EQ(got[i].count, runs[i].count);
  }
  const std::vector<uint8_t> stored(100, 0x5a);
  const std::vector<uint8_t> bytes9 = EncodeBlockData(2, BlockDataHeader{42, 3, 0, 0}, stored);
  const Expected<Message> d = Decode(bytes9, 2);
  ASSERT_TRUE(d.ok()) << d.status().message();
  EXPECT_EQ(d->block_data_header().runs, 3u);
  EXPECT_EQ(d->block_data().size(), stored.size());
}

TEST(Message, HostileBlockRequestsAndAnswersAreRefused) {
  const std::vector<BlockRun> runs = {{10, 2}, {40, 1}};
  std::vector<uint8_t> b = EncodeBlockRequest(1, 0, runs);
  Poke<uint32_t>(&b, sizeof(MessageHeader) + 4, 0);  // no runs
  ExpectError(b, 1, "block request of 0 runs");
  b = EncodeBlockRequest(1, 0, runs);
  Poke<uint32_t>(&b, sizeof(MessageHeader) + 4, kMaxRequestRuns + 1);
  ExpectError(b, 1, "block request of " + std::to_string(kMaxRequestRuns + 1) + " runs");
  b = EncodeBlockRequest(1, 0, runs);
  Poke<uint32_t>(&b, sizeof(MessageHeader) + 4, 3);  // one more than sent
  ExpectError(b, 1, "block request of 3 runs in");
  b = EncodeBlockRequest(1, 0, runs);
  b.resize(sizeof(MessageHeader) + 8);
  Poke<uint32_t>(&b, 12, 8);
  ExpectError(b, 1, "block request without its count");
  b = EncodeBlockData(1, BlockDataHeader{0, 0, 0, 0}, std::vector<uint8_t>(8));
  ExpectError(b, 1, "block data of 0 runs");
  b = EncodeBlockData(1, BlockDataHeader{0, 1, 1, 0}, std::vector<uint8_t>(8));
  ExpectError(b, 1, "bad failure flag");  // failed, yet with bytes
}

TEST(Message, NoTruncationOrFlippedByteCrashesOrMisreads) {
  std::vector<render::SampleResult> samples(3, Sample(5));
  const std::vector<std::vector<uint8_t>> messages = {
      Encode(2, TileAssign{1, 0, 0, 0, 32, 32, 0, 0, 1, 0, 256}), EncodePixelBatch(2, 1, samples),
      Encode(2, FrameDone{1, 2, 9, 0, 0, 0, 0, 0, 0.5, 0, 0, 0, 0, 0, 0, 0, 0, 0,
                          kFrameDoneDirectReads, 0, 0.25, 0.125, 0.75, {5, 4, 3, 2}, 7, 11,
                          0.5, 0.25, 1 << 20, 1 << 19, 3, 4096, 64, 1 << 24})};
  for (const auto& good : messages) {
    for (size_t n = 0; n < good.size(); ++n)  // every truncation
      EXPECT_FALSE(Decode(std::span(good).first(n), 2).ok()) << n;
    for (size_t i = 0; i < good.size(); ++i) {  // every byte flipped: refused, or header intact
      std::vector<uint8_t> b = good;
      b[i] ^= 0xff;
      const Expected<Message> m = Decode(b, 2);
      if (m.ok()) {
        EXPECT_GE(i, sizeof(MessageHeader));  // only payload values can change unnoticed
        EXPECT_EQ(m->payload.size(), good.size() - sizeof(MessageHeader));
      }
    }
  }
}

}  // namespace
}  // namespace raystack::wire
