// The transport contract over MPI, run by ctest under `mpirun -np 3`: every rank sends to every
// other rank, messages arrive in order per pair, a hostile message (forged sender, another
// protocol version) is refused naming the rank it came from, receive times out when idle, and
// two ranks posting each other large messages before either receives both get theirs, and
// the bytes they posted count as posted until then only.
// Prints "N passed, N failed" on rank 0; exit code 0 only if every rank passed.

#include <chrono>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

#include "common/mpi/mpi_transport.h"
#include "common/wire/message.h"

using namespace raystack;

namespace {

int failures = 0, passes = 0;

void Expect(bool ok, const std::string& what, int rank) {
  if (ok) {
    ++passes;
  } else {
    ++failures;
    std::fprintf(stderr, "rank %d: FAILED: %s\n", rank, what.c_str());
  }
}

}  // namespace

int main(int argc, char** argv) {
  Expected<std::unique_ptr<mpi::MpiTransport>> t = mpi::MpiTransport::Init(&argc, &argv);
  if (!t.ok()) {
    std::fprintf(stderr, "%s\n", t.status().message().c_str());
    return 1;
  }
  transport::Transport& net = **t;
  const int rank = net.rank(), size = net.size();
  Expect(size == 3, "run with -np 3", rank);
  constexpr uint32_t kMessages = 200;

  // 1. Everyone sends kMessages numbered requests to everyone else, then reads its own.
  for (uint32_t i = 0; i < kMessages; ++i)
    for (int to = 0; to < size; ++to)
      if (to != rank)
        Expect(net.Send(to, wire::Encode(static_cast<uint32_t>(rank), wire::TileRequest{i, 0})).ok(),
               "send", rank);
  // 2. Rank 1 then sends rank 0 a message forging rank 2 and one of another protocol version;
  //    ranks 1 and 2 send rank 0 their verdicts once they have read everything.
  // Rank 0 reads whatever comes (per pair the order holds; across senders it may interleave).
  std::vector<uint32_t> next(static_cast<size_t>(size), 0);
  std::vector<std::string> refusals;
  int verdicts = 0;
  auto done = [&] {
    for (int r = 0; r < size; ++r)
      if (r != rank && next[r] < kMessages) return false;
    return rank != 0 || (verdicts == size - 1 && refusals.size() == 2);
  };
  while (!done()) {
    auto e = net.Receive(std::chrono::seconds(30));
    if (!e.ok() || !e->has_value()) {
      Expect(false, "every message arrives", rank);
      break;
    }
    const int from = (*e)->from;
    const Expected<wire::Message> m = wire::Decode((*e)->bytes, from);
    if (!m.ok()) {
      refusals.push_back(m.status().message());
      continue;
    }
    if (m->type() == wire::MessageType::kTileRequest) {
      Expect(m->tile_request().frame == next[from]++, "in order per sender", rank);
    } else if (m->type() == wire::MessageType::kFrameDone) {
      Expect(next[from] == kMessages, "a verdict comes after the sender's requests", rank);
      ++verdicts;
      failures += static_cast<int>(m->frame_done().frame);
      passes += static_cast<int>(m->frame_done().samples);
    } else {
      Expect(false, "an expected message type", rank);
    }
  }
  // 3. Ranks 1 and 2 each post the other large messages (beyond any eager limit, so MPI waits
  //    for the receiver) before either receives: posting never waits for the peer (two slaves
  //    answering each other's block requests on their receiving threads), and the bytes arrive
  //    whole and in order.
  if (rank == 1 || rank == 2) {
    const int peer = 3 - rank;
    constexpr int kPosts = 4;
    constexpr size_t kBytes = 1 << 20;
    auto pattern = [](int from, int i, size_t k) {
      return static_cast<uint8_t>(from * 31 + i * 7 + static_cast<int>(k % 251));
    };
    for (int i = 0; i < kPosts; ++i) {
      std::vector<uint8_t> bytes(kBytes);
      for (size_t k = 0; k < kBytes; ++k) bytes[k] = pattern(rank, i, k);
      Expect(net.Post(peer, std::move(bytes)).ok(), "post", rank);
    }
    for (int i = 0; i < kPosts; ++i) {
      auto e = net.Receive(std::chrono::seconds(30));
      if (!e.ok() || !e->has_value() || (*e)->from != peer || (*e)->bytes.size() != kBytes) {
        Expect(false, "every posted message arrives from the peer, whole", rank);
        break;
      }
      bool same = true;
      for (size_t k = 0; k < kBytes && same; ++k) same = (*e)->bytes[k] == pattern(peer, i, k);
      Expect(same, "posted bytes arrive intact and in order", rank);
    }
    // Once the peer has taken them, the posted sends are done and their bytes are let go (a
    // stream's sender bounds its backlog by posted_bytes, so it must come back to zero).
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (net.posted_bytes() > 0 && std::chrono::steady_clock::now() < deadline)
      (void)net.Receive(std::chrono::milliseconds(10));
    Expect(net.posted_bytes() == 0, "posted bytes come back to zero once taken", rank);
  }
  if (rank == 1) {
    Expect(net.Send(0, wire::Encode(2, wire::TileRequest{0, 0})).ok(), "send forged", rank);
    std::vector<uint8_t> other = wire::Encode(1, wire::TileRequest{0, 0});
    other[4] = 99;  // version 99, never this build's
    Expect(net.Send(0, other).ok(), "send other version", rank);
  }
  if (rank != 0) {
    wire::FrameDone verdict{};
    verdict.frame = static_cast<uint32_t>(failures);
    verdict.samples = static_cast<uint64_t>(passes);
    Expect(net.Send(0, wire::Encode(static_cast<uint32_t>(rank), verdict)).ok(), "send verdict",
           rank);
  } else {
    for (const char* expected :
         {"rank 1: claims to come from rank 2", "rank 1: protocol version 99"}) {
      bool found = false;
      for (const std::string& r : refusals) found = found || r.find(expected) != std::string::npos;
      Expect(found, std::string("refused: ") + expected, rank);
    }
    // Nothing else is on its way: a receive times out.
    auto e = net.Receive(std::chrono::milliseconds(50));
    Expect(e.ok() && !e->has_value(), "idle receive times out", rank);
    // 4. With an idle pause, a receive that nothing waits for looks once a pause (at the
    //    quickest pace it would look every 0.5-1 ms, ~200 times here) ...
    mpi::MpiTransport& mpi_net = **t;
    net.SetIdlePause(std::chrono::milliseconds(50));
    uint64_t before = mpi_net.probes();
    e = net.Receive(std::chrono::milliseconds(200));
    Expect(e.ok() && !e->has_value(), "idle receive with an idle pause times out", rank);
    const uint64_t idle_probes = mpi_net.probes() - before;
    Expect(idle_probes >= 2 && idle_probes <= 200 / 50 + 2,
           "an idle receive looks once per idle pause (" + std::to_string(idle_probes) + " looks)",
           rank);
    //    ... and a thread that begins to wait for an answer wakes it from its pause: looks at
    //    the quickest pace from then on (without the wake: one look in the whole receive).
    net.SetIdlePause(std::chrono::seconds(60));
    before = mpi_net.probes();
    std::thread receiver([&] { e = net.Receive(std::chrono::milliseconds(500)); });
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    {
      transport::AnswerWait waiting(&net);
      receiver.join();
    }
    const uint64_t hurried_probes = mpi_net.probes() - before;
    Expect(hurried_probes > 20, "a waiting thread wakes the receive from its idle pause (" +
                                    std::to_string(hurried_probes) + " looks)", rank);
    net.SetIdlePause(std::chrono::microseconds(0));
    std::printf("%d passed, %d failed\n", passes, failures);
  }
  return failures == 0 ? 0 : 1;
}
