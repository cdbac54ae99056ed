// How fast the master checks incoming samples against the tiles in flight (master/TileLedger),
// as the cluster grows: SLAVES ranks of THREADS ray threads, each thread holding PER_THREAD
// tiles of 32 x 32 pixels and 16 samples, and batches of 1,024 samples from one thread whose
// samples interleave its tiles (the worst order for the search's "last tile" guess). Measures;
// never run as a test.
//
//   build/tools/bench/ledger_bench SLAVES THREADS PER_THREAD [BATCHES]

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

#include "master/tile_ledger.h"

using raystack::master::TileLedger;
using raystack::render::SampleResult;
using raystack::render::Tile;

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: ledger_bench SLAVES THREADS PER_THREAD [BATCHES]\n");
    return 2;
  }
  const int slaves = std::atoi(argv[1]), threads = std::atoi(argv[2]), per_thread = std::atoi(argv[3]);
  const int batches = argc > 4 ? std::atoi(argv[4]) : 20;
  constexpr int kWidth = 16384, kSide = 32, kSamples = 16, kBatch = 1024;
  const int tiles_a_row = kWidth / kSide;
  if (slaves < 1 || threads < 1 || per_thread < 1 || batches < 1 ||
      int64_t{slaves} * threads * per_thread > int64_t{tiles_a_row} * tiles_a_row ||
      int64_t{batches} * kBatch > int64_t{per_thread} * kSide * kSide * kSamples) {
    std::fprintf(stderr, "ledger_bench: sizes out of range\n");
    return 2;
  }
  TileLedger ledger(kWidth, kSamples);
  std::vector<Tile> measured;  // the tiles of the last rank's last thread
  int k = 0;
  for (int rank = 1; rank <= slaves; ++rank)
    for (int t = 0; t < threads; ++t)
      for (int j = 0; j < per_thread; ++j, ++k) {
        const int x = (k % tiles_a_row) * kSide, y = (k / tiles_a_row) * kSide;
        const Tile tile{x, y, x + kSide, y + kSide, 0, kSamples};
        ledger.Assign(tile, rank);
        if (rank == slaves && t == threads - 1) measured.push_back(tile);
      }
  std::mt19937 rng(1);
  std::vector<int> sent(measured.size(), 0);
  std::vector<SampleResult> batch(kBatch);
  double seconds = 0;
  for (int b = 0; b < batches; ++b) {
    for (SampleResult& s : batch) {
      size_t j = rng() % measured.size();
      while (sent[j] == kSide * kSide * kSamples) j = (j + 1) % measured.size();
      const int n = sent[j]++;
      const Tile& tile = measured[j];
      s = {};
      s.pixel = static_cast<uint32_t>((tile.y0 + n % (kSide * kSide) / kSide) * kWidth + tile.x0 +
                                      n % kSide);
      s.sample = static_cast<uint32_t>(n / (kSide * kSide));
    }
    const auto start = std::chrono::steady_clock::now();
    const raystack::Status status = ledger.Record(slaves, batch);
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (!status.ok()) {
      std::fprintf(stderr, "ledger_bench: %s\n", status.message().c_str());
      return 1;
    }
  }
  std::printf("%d slaves x %d threads x %d tiles (%zu in flight): %.2f M samples/s\n", slaves,
              threads, per_thread, ledger.unfinished(), batches * kBatch / seconds / 1e6);
  return 0;
}
