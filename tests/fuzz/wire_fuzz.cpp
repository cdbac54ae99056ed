// libFuzzer target: the decoder of messages between ranks. A message it accepts is read
// through the typed view of its type, as the master and slaves do.
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "common/base/check.h"
#include "common/wire/message.h"
#include "tests/fuzz/fuzz_quiet.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace raystack::wire;
  constexpr int kFrom = 1;
  raystack::Expected<Message> m = Decode(std::span<const uint8_t>(data, size), kFrom);
  if (!m.ok()) {
    CHECK(!m.status().message().empty());
    return 0;
  }
  CHECK(m->header.sender == kFrom);
  switch (m->type()) {
    case MessageType::kHello: (void)m->hello(); break;
    case MessageType::kTileRequest: (void)m->tile_request(); break;
    case MessageType::kTileAssign: (void)m->tile_assign(); break;
    case MessageType::kFrameDone: (void)m->frame_done(); break;
    case MessageType::kShutdown: (void)m->shutdown(); break;
    case MessageType::kError: (void)m->error_text(); break;
    case MessageType::kBlockRequest: (void)m->block_request(); break;
    case MessageType::kHeartbeat: (void)m->heartbeat(); break;
    case MessageType::kRankLost: (void)m->rank_lost(); break;
    case MessageType::kBlockData: {
      (void)m->block_data_header();
      (void)m->block_data();
      break;
    }
    case MessageType::kPixelBatch: {
      const PixelBatchHeader h = m->batch_header();
      std::vector<raystack::render::SampleResult> samples;
      m->batch_samples(&samples);
      CHECK(samples.size() == h.count);
      break;
    }
  }
  return 0;
}
