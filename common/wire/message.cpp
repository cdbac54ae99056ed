#include "common/wire/message.h"

#include <algorithm>
#include <cstring>
#include <limits>

#include "common/base/check.h"
#include "common/base/log.h"

namespace raystack::wire {
namespace {

// A whole message: the header, `head` (the payload's fixed part), `tail` (its records or
// bytes, if any), then `room` zero bytes for the caller to fill.
std::vector<uint8_t> Assemble(uint32_t sender, MessageType type, std::span<const uint8_t> head,
                              std::span<const uint8_t> tail = {}, uint64_t room = 0) {
  const uint64_t payload = head.size() + tail.size() + room;
  CHECK(payload <= 0xffffffffu);
  std::vector<uint8_t> bytes(sizeof(MessageHeader) + payload);
  const MessageHeader h{kMagic, kProtocolVersion, static_cast<uint16_t>(type), sender,
                        static_cast<uint32_t>(payload)};
  std::memcpy(bytes.data(), &h, sizeof h);
  if (!head.empty()) std::memcpy(bytes.data() + sizeof h, head.data(), head.size());
  if (!tail.empty()) std::memcpy(bytes.data() + sizeof h + head.size(), tail.data(), tail.size());
  return bytes;
}

template <typename T>
std::span<const uint8_t> BytesOf(const T& value) {
  return {reinterpret_cast<const uint8_t*>(&value), sizeof value};
}

template <typename T>
std::vector<uint8_t> Build(uint32_t sender, MessageType type, const T& payload) {
  return Assemble(sender, type, BytesOf(payload));
}

// Payload size a type must have (pixel batches: their header's; checked separately).
uint64_t FixedPayloadBytes(MessageType type) {
  switch (type) {
    case MessageType::kHello: return sizeof(Hello);
    case MessageType::kTileRequest: return sizeof(TileRequest);
    case MessageType::kTileAssign: return sizeof(TileAssign);
    case MessageType::kFrameDone: return sizeof(FrameDone);
    case MessageType::kShutdown: return sizeof(Shutdown);
    case MessageType::kHeartbeat: return sizeof(Heartbeat);
    case MessageType::kRankLost: return sizeof(RankLost);
    case MessageType::kPixelBatch:
    case MessageType::kBlockRequest:
    case MessageType::kBlockData:
    case MessageType::kError: return 0;
  }
  return 0;
}

template <typename T>
T PayloadAs(const Message& m, MessageType type) {
  CHECK(m.type() == type && m.payload.size() == sizeof(T));
  T out;
  std::memcpy(&out, m.payload.data(), sizeof out);
  return out;
}

}  // namespace

const char* MessageTypeName(MessageType type) {
  switch (type) {
    case MessageType::kHello: return "hello";
    case MessageType::kTileRequest: return "tile request";
    case MessageType::kTileAssign: return "tile assignment";
    case MessageType::kPixelBatch: return "pixel batch";
    case MessageType::kFrameDone: return "frame done";
    case MessageType::kShutdown: return "shutdown";
    case MessageType::kError: return "error";
    case MessageType::kBlockRequest: return "block request";
    case MessageType::kBlockData: return "block data";
    case MessageType::kHeartbeat: return "heartbeat";
    case MessageType::kRankLost: return "rank lost";
  }
  return "unknown";
}

std::string HelloText(const char (&field)[40]) {
  std::string text;
  for (const char c : field) {
    if (c == '\0') break;
    text += c >= 0x20 && c < 0x7f ? c : '?';
  }
  return text;
}

void SetHelloText(char (&field)[40], const std::string& text) {
  std::memset(field, 0, sizeof field);
  std::memcpy(field, text.data(), std::min(text.size(), sizeof field - 1));
}

std::vector<uint8_t> Encode(uint32_t sender, const Hello& m) {
  return Build(sender, MessageType::kHello, m);
}
std::vector<uint8_t> Encode(uint32_t sender, const TileRequest& m) {
  return Build(sender, MessageType::kTileRequest, m);
}
std::vector<uint8_t> Encode(uint32_t sender, const TileAssign& m) {
  return Build(sender, MessageType::kTileAssign, m);
}
std::vector<uint8_t> Encode(uint32_t sender, const FrameDone& m) {
  return Build(sender, MessageType::kFrameDone, m);
}
std::vector<uint8_t> Encode(uint32_t sender, const Shutdown& m) {
  return Build(sender, MessageType::kShutdown, m);
}

std::vector<uint8_t> EncodeBlockRequest(uint32_t sender, uint32_t request,
                                        std::span<const BlockRun> runs) {
  CHECK(!runs.empty() && runs.size() <= kMaxRequestRuns);
  const BlockRequest r{request, static_cast<uint32_t>(runs.size()), {0, 0}};
  return Assemble(sender, MessageType::kBlockRequest, BytesOf(r),
                  {reinterpret_cast<const uint8_t*>(runs.data()), runs.size_bytes()});
}

std::vector<uint8_t> Encode(uint32_t sender, const Heartbeat& m) {
  return Build(sender, MessageType::kHeartbeat, m);
}
std::vector<uint8_t> Encode(uint32_t sender, const RankLost& m) {
  return Build(sender, MessageType::kRankLost, m);
}

std::vector<uint8_t> EncodeBlockData(uint32_t sender, const BlockDataHeader& d,
                                     std::span<const uint8_t> stored) {
  return Assemble(sender, MessageType::kBlockData, BytesOf(d), stored);
}

std::vector<uint8_t> EncodeError(uint32_t sender, const std::string& text) {
  const size_t n = std::min<size_t>(text.size(), kMaxErrorText);
  return Assemble(sender, MessageType::kError,
                  {reinterpret_cast<const uint8_t*>(text.data()), n});
}

std::vector<uint8_t> EncodePixelBatch(uint32_t sender, uint32_t frame,
                                      std::span<const render::SampleResult> samples,
                                      uint64_t rays) {
  CHECK(samples.size() <= kMaxBatchSamples);
  uint32_t primary = 0;
  for (const render::SampleResult& s : samples) primary += s.sample == 0 ? 1 : 0;
  const PixelBatchHeader b{frame, static_cast<uint32_t>(samples.size()), rays, primary, 0};
  std::vector<uint8_t> bytes = Assemble(
      sender, MessageType::kPixelBatch, BytesOf(b), {},
      samples.size() * sizeof(SampleRecord) + uint64_t{primary} * sizeof(PrimaryRecord));
  uint8_t* const records = bytes.data() + sizeof(MessageHeader) + sizeof b;
  uint8_t* const primaries = records + samples.size() * sizeof(SampleRecord);
  // Sample-0 records first, with their primary layers; then the others. Each in batch order.
  size_t next_primary = 0, next_other = primary;
  for (const render::SampleResult& s : samples) {
    CHECK(s.sample < kSampleHit);  // (scenes allow 65535 samples a pixel)
    const SampleRecord r{s.pixel, s.sample | (s.hit ? kSampleHit : 0),
                         {s.rgb[0], s.rgb[1], s.rgb[2]}};
    if (s.sample != 0) {
      std::memcpy(records + next_other++ * sizeof r, &r, sizeof r);
      continue;
    }
    const PrimaryRecord p{s.z,
                          {s.normal[0], s.normal[1], s.normal[2]},
                          {s.albedo[0], s.albedo[1], s.albedo[2]}};
    std::memcpy(records + next_primary * sizeof r, &r, sizeof r);
    std::memcpy(primaries + next_primary++ * sizeof p, &p, sizeof p);
  }
  return bytes;
}

bool SpeaksThisProtocol(std::span<const uint8_t> bytes) {
  MessageHeader h{};
  if (bytes.size() < sizeof h) return false;
  std::memcpy(&h, bytes.data(), sizeof h);
  return h.magic == kMagic && h.version == kProtocolVersion;
}

Expected<Message> Decode(std::span<const uint8_t> bytes, int from) {
  auto bad = [&](const std::string& what) {
    return Status::Error(StrFormat("message from rank %d: %s", from, what.c_str()));
  };
  Message m;
  if (bytes.size() < sizeof(MessageHeader))
    return bad(StrFormat("%zu bytes, shorter than a message header", bytes.size()));
  std::memcpy(&m.header, bytes.data(), sizeof m.header);
  const MessageHeader& h = m.header;
  if (h.magic != kMagic) return bad(StrFormat("not a raystack message (magic %08x)", h.magic));
  if (h.version != kProtocolVersion)
    return bad(StrFormat("protocol version %u, this build speaks %u (run the same raystack "
                         "build on every rank)", h.version, kProtocolVersion));
  if (h.type == 0 || h.type > kMessageTypeCount) return bad(StrFormat("unknown type %u", h.type));
  if (h.sender != static_cast<uint32_t>(from))
    return bad(StrFormat("claims to come from rank %u", h.sender));
  if (uint64_t{h.payload_bytes} != bytes.size() - sizeof(MessageHeader))
    return bad(StrFormat("%s: header says %u payload bytes, %zu arrived",
                         MessageTypeName(m.type()), h.payload_bytes,
                         bytes.size() - sizeof(MessageHeader)));
  m.payload = bytes.subspan(sizeof(MessageHeader));
  if (m.type() == MessageType::kPixelBatch) {
    if (m.payload.size() < sizeof(PixelBatchHeader))
      return bad("pixel batch without its count");
    PixelBatchHeader b;
    std::memcpy(&b, m.payload.data(), sizeof b);
    if (b.count > kMaxBatchSamples)
      return bad(StrFormat("pixel batch of %u samples (at most %u)", b.count, kMaxBatchSamples));
    if (b.primary > b.count)
      return bad(StrFormat("pixel batch of %u samples, %u of them sample 0", b.count, b.primary));
    if (m.payload.size() != sizeof b + uint64_t{b.count} * sizeof(SampleRecord) +
                                uint64_t{b.primary} * sizeof(PrimaryRecord))
      return bad(StrFormat("pixel batch of %u samples (%u sample 0) in %zu bytes", b.count,
                           b.primary, m.payload.size()));
    // The primary layers belong to the first `primary` samples: exactly the sample-0 ones.
    for (uint32_t i = 0; i < b.count; ++i) {
      SampleRecord r;
      std::memcpy(&r, m.payload.data() + sizeof b + uint64_t{i} * sizeof r, sizeof r);
      if (((r.sample & ~kSampleHit) == 0) != (i < b.primary))
        return bad(StrFormat("pixel batch: its sample %u (pixel %u, sample %u) %s", i, r.pixel,
                             r.sample & ~kSampleHit,
                             i < b.primary ? "should be a sample 0" : "is a sample 0 without "
                                                                      "its primary layers"));
    }
  } else if (m.type() == MessageType::kBlockRequest) {
    if (m.payload.size() < sizeof(BlockRequest)) return bad("block request without its count");
    BlockRequest r;
    std::memcpy(&r, m.payload.data(), sizeof r);
    if (r.runs == 0 || r.runs > kMaxRequestRuns)
      return bad(StrFormat("block request of %u runs (1 to %u)", r.runs, kMaxRequestRuns));
    if (m.payload.size() != sizeof r + uint64_t{r.runs} * sizeof(BlockRun))
      return bad(StrFormat("block request of %u runs in %zu bytes", r.runs, m.payload.size()));
  } else if (m.type() == MessageType::kBlockData) {
    if (m.payload.size() < sizeof(BlockDataHeader)) return bad("block data without its header");
    BlockDataHeader d;
    std::memcpy(&d, m.payload.data(), sizeof d);
    if (d.failed > 1 || (d.failed && m.payload.size() != sizeof d))
      return bad("block data with a bad failure flag");
    if (d.runs == 0 || d.runs > kMaxRequestRuns)
      return bad(StrFormat("block data of %u runs (1 to %u)", d.runs, kMaxRequestRuns));
  } else if (m.type() == MessageType::kError) {
    if (m.payload.size() > kMaxErrorText)
      return bad(StrFormat("error text of %zu bytes (at most %u)", m.payload.size(), kMaxErrorText));
  } else if (m.payload.size() != FixedPayloadBytes(m.type())) {
    return bad(StrFormat("%s of %zu bytes, expected %llu", MessageTypeName(m.type()),
                         m.payload.size(),
                         static_cast<unsigned long long>(FixedPayloadBytes(m.type()))));
  }
  return m;
}

Hello Message::hello() const { return PayloadAs<Hello>(*this, MessageType::kHello); }
TileRequest Message::tile_request() const {
  return PayloadAs<TileRequest>(*this, MessageType::kTileRequest);
}
TileAssign Message::tile_assign() const {
  return PayloadAs<TileAssign>(*this, MessageType::kTileAssign);
}
FrameDone Message::frame_done() const {
  return PayloadAs<FrameDone>(*this, MessageType::kFrameDone);
}
Shutdown Message::shutdown() const { return PayloadAs<Shutdown>(*this, MessageType::kShutdown); }

PixelBatchHeader Message::batch_header() const {
  CHECK(type() == MessageType::kPixelBatch && payload.size() >= sizeof(PixelBatchHeader));
  PixelBatchHeader b;
  std::memcpy(&b, payload.data(), sizeof b);
  return b;
}

std::string Message::error_text() const {
  CHECK(type() == MessageType::kError);
  std::string text(reinterpret_cast<const char*>(payload.data()), payload.size());
  for (char& c : text)  // a hostile text cannot drive the terminal
    if (static_cast<unsigned char>(c) < 0x20 && c != '\n') c = '?';
  return text;
}

BlockRequest Message::block_request() const {
  CHECK(type() == MessageType::kBlockRequest && payload.size() >= sizeof(BlockRequest));
  BlockRequest r;
  std::memcpy(&r, payload.data(), sizeof r);
  return r;
}

void Message::block_runs(std::vector<BlockRun>* out) const {
  const BlockRequest r = block_request();
  out->resize(r.runs);
  std::memcpy(out->data(), payload.data() + sizeof r, uint64_t{r.runs} * sizeof(BlockRun));
}
Heartbeat Message::heartbeat() const { return PayloadAs<Heartbeat>(*this, MessageType::kHeartbeat); }
RankLost Message::rank_lost() const { return PayloadAs<RankLost>(*this, MessageType::kRankLost); }

BlockDataHeader Message::block_data_header() const {
  CHECK(type() == MessageType::kBlockData && payload.size() >= sizeof(BlockDataHeader));
  BlockDataHeader d;
  std::memcpy(&d, payload.data(), sizeof d);
  return d;
}

std::span<const uint8_t> Message::block_data() const {
  CHECK(type() == MessageType::kBlockData);
  return payload.subspan(sizeof(BlockDataHeader));
}

void Message::batch_samples(std::vector<render::SampleResult>* out) const {
  const PixelBatchHeader b = batch_header();
  out->resize(b.count);
  const uint8_t* const records = payload.data() + sizeof b;
  const uint8_t* const primaries = records + uint64_t{b.count} * sizeof(SampleRecord);
  for (uint32_t i = 0; i < b.count; ++i) {
    SampleRecord r;
    std::memcpy(&r, records + uint64_t{i} * sizeof r, sizeof r);
    render::SampleResult& s = (*out)[i];
    s.pixel = r.pixel;
    s.sample = r.sample & ~kSampleHit;
    s.hit = (r.sample & kSampleHit) ? 1 : 0;
    for (int c = 0; c < 3; ++c) s.rgb[c] = r.rgb[c];
    PrimaryRecord p{std::numeric_limits<float>::infinity(), {0, 0, 0}, {0, 0, 0}};
    if (i < b.primary) std::memcpy(&p, primaries + uint64_t{i} * sizeof p, sizeof p);
    s.z = p.z;
    for (int c = 0; c < 3; ++c) {
      s.normal[c] = p.normal[c];
      s.albedo[c] = p.albedo[c];
    }
  }
}

}  // namespace raystack::wire
