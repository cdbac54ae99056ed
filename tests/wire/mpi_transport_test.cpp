// The transport contract over MPI, run by ctest under `mpirun -np 3`: every rank sends to every
// other rank, messages arrive in order per pair, a hostile message (forged sender, another
// protocol version) is refused naming the rank it came from, and receive times out when idle.
// Prints "N passed, N failed" on rank 0; exit code 0 only if every rank passed.

#include <cstdio>
#include <string>
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
  std::vector<uint32_t> next(static_cast<size_t>(size), 0);
  for (uint32_t n = 0; n < kMessages * static_cast<uint32_t>(size - 1); ++n) {
    auto e = net.Receive(std::chrono::seconds(30));
    if (!e.ok() || !e->has_value()) {
      Expect(false, "a message arrives", rank);
      break;
    }
    const Expected<wire::Message> m = wire::Decode((*e)->bytes, (*e)->from);
    Expect(m.ok() && m->tile_request().frame == next[(*e)->from]++, "in order per sender", rank);
  }
  for (int r = 0; r < size; ++r)
    if (r != rank) Expect(next[r] == kMessages, "all messages from rank " + std::to_string(r), rank);

  // 2. Rank 1 sends rank 0 a message forging rank 2 and one of another protocol version.
  if (rank == 1) {
    Expect(net.Send(0, wire::Encode(2, wire::TileRequest{0, 0})).ok(), "send forged", rank);
    std::vector<uint8_t> other = wire::Encode(1, wire::TileRequest{0, 0});
    other[4] = 9;  // version 9
    Expect(net.Send(0, other).ok(), "send other version", rank);
  }
  // Everyone's verdict goes to rank 0, which also checks the hostile messages (they and the
  // verdicts may arrive in any order across senders) and prints the total.
  if (rank != 0) {
    Expect(net.Send(0, wire::Encode(static_cast<uint32_t>(rank),
                                    wire::FrameDone{static_cast<uint32_t>(failures), 0,
                                                    static_cast<uint64_t>(passes)})).ok(),
           "send verdict", rank);
  } else {
    std::vector<std::string> refusals;
    int verdicts = 0;
    while (verdicts < size - 1 || refusals.size() < 2) {
      auto e = net.Receive(std::chrono::seconds(30));
      if (!e.ok() || !e->has_value()) {
        Expect(false, "every verdict and hostile message arrives", rank);
        break;
      }
      const Expected<wire::Message> m = wire::Decode((*e)->bytes, (*e)->from);
      if (!m.ok()) {
        refusals.push_back(m.status().message());
        continue;
      }
      ++verdicts;
      failures += static_cast<int>(m->frame_done().frame);
      passes += static_cast<int>(m->frame_done().samples);
    }
    for (const char* expected : {"rank 1: claims to come from rank 2", "rank 1: protocol version 9"}) {
      bool found = false;
      for (const std::string& r : refusals) found = found || r.find(expected) != std::string::npos;
      Expect(found, std::string("refused: ") + expected, rank);
    }
    // Nothing else is on its way: a receive times out.
    auto e = net.Receive(std::chrono::milliseconds(50));
    Expect(e.ok() && !e->has_value(), "idle receive times out", rank);
    std::printf("%d passed, %d failed\n", passes, failures);
  }
  return failures == 0 ? 0 : 1;
}
