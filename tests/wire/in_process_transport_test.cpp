// The in-process transport: ranks as threads exchange messages in order per pair, a receive
// times out when nothing comes, and bad destinations or sizes are errors.

#include <gtest/gtest.h>

#include <thread>
#include <vector>

#include "common/transport/transport.h"
#include "common/wire/message.h"

namespace raystack::transport {
namespace {

TEST(InProcessTransport, RanksExchangeMessagesInOrderPerPair) {
  constexpr int kRanks = 4, kMessages = 500;
  InProcessHub hub(kRanks);
  std::vector<std::unique_ptr<Transport>> ends;
  for (int r = 0; r < kRanks; ++r) ends.push_back(hub.Endpoint(r));
  // Every rank but 0 sends kMessages numbered requests to rank 0 from its own thread.
  std::vector<std::thread> senders;
  for (int r = 1; r < kRanks; ++r)
    senders.emplace_back([&, r] {
      for (uint32_t i = 0; i < kMessages; ++i)
        ASSERT_TRUE(ends[r]->Send(0, wire::Encode(static_cast<uint32_t>(r),
                                                  wire::TileRequest{i, 0})).ok());
    });
  std::vector<uint32_t> next(kRanks, 0);
  for (int n = 0; n < (kRanks - 1) * kMessages; ++n) {
    Expected<std::optional<Envelope>> e = ends[0]->Receive(std::chrono::seconds(10));
    ASSERT_TRUE(e.ok() && e->has_value());
    const Expected<wire::Message> m = wire::Decode((*e)->bytes, (*e)->from);
    ASSERT_TRUE(m.ok()) << m.status().message();
    EXPECT_EQ(m->tile_request().frame, next[(*e)->from]++);  // in order per sender
  }
  for (std::thread& t : senders) t.join();
  for (int r = 1; r < kRanks; ++r) EXPECT_EQ(next[r], static_cast<uint32_t>(kMessages));
}

TEST(InProcessTransport, ReceiveTimesOutWhenNothingComes) {
  InProcessHub hub(2);
  auto end = hub.Endpoint(1);
  Expected<std::optional<Envelope>> e = end->Receive(std::chrono::milliseconds(20));
  ASSERT_TRUE(e.ok());
  EXPECT_FALSE(e->has_value());
}

TEST(InProcessTransport, BadDestinationOrSizeIsAnError) {
  InProcessHub hub(2);
  auto end = hub.Endpoint(0);
  const std::vector<uint8_t> small(8);
  EXPECT_FALSE(end->Send(2, small).ok());
  EXPECT_FALSE(end->Send(-1, small).ok());
  const std::vector<uint8_t> huge(kMaxMessageBytes + 1);
  const Status s = end->Send(1, huge);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("too large"), std::string::npos) << s.message();
}

}  // namespace
}  // namespace raystack::transport
