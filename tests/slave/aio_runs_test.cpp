// Direct reads kept in flight with Linux AIO (slave/aio_runs.h): the bytes equal buffered
// reads for every block and for runs, with every slot in flight, started one by one or in
// batches (Prepare, SubmitPrepared); injected faults and a file cut short while open come
// back as errors naming the file; buffered stores do not use it.

#include "slave/aio_runs.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <map>

#include "slave/block_source.h"
#include "tests/slave/render_fixture.h"

namespace raystack::testing {
namespace {

using slave::AioRuns;

struct BlockRun {
  uint32_t first, last;
};

std::vector<uint8_t> Buffered(const store::StoreReader& store, BlockRun run) {
  const store::StoreReader::Extent extent = store.RunExtent(run.first, run.last);
  std::vector<uint8_t> bytes(extent.size);
  EXPECT_TRUE(store.ReadRange(extent.offset, extent.size, bytes.data()).ok());
  return bytes;
}

std::vector<uint32_t> Ids(BlockRun run) {
  std::vector<uint32_t> ids;
  for (uint32_t i = run.first; i <= run.last; ++i) ids.push_back(i);
  return ids;
}

using Outcomes = std::map<size_t, std::pair<Status, std::vector<uint8_t>>>;

// Reads `runs` with up to `depth` in flight, each started alone or (`batched`) all that fit
// in one submission; returns each run's outcome, by index.
Outcomes ReadAll(AioRuns* aio, const std::vector<BlockRun>& runs, int depth, bool* filled,
                 bool batched = false) {
  Outcomes out;
  std::map<int, size_t> by_slot;
  size_t next = 0;
  std::vector<AioRuns::Finished> finished;
  while (out.size() < runs.size()) {
    while (next < runs.size()) {
      const int slot = batched ? aio->Prepare(Ids(runs[next])) : aio->Start(Ids(runs[next]));
      if (slot < 0) {
        *filled = true;
        EXPECT_EQ(aio->in_flight(), depth);
        break;
      }
      by_slot[slot] = next++;
    }
    if (batched) aio->SubmitPrepared();
    finished.clear();
    aio->Wait(1000, 64, &finished);
    for (const AioRuns::Finished& f : finished) {
      out[by_slot.at(f.slot)] = {f.status, std::vector<uint8_t>(f.bytes.begin(), f.bytes.end())};
      aio->Release(f.slot);
    }
  }
  EXPECT_EQ(aio->in_flight(), 0);
  return out;
}

TEST(AioRuns, ReadsWhatBufferedReadsRead) {
  TestStore s = BuildGenerated("spheres:30000");
  std::unique_ptr<store::StoreReader> direct = OpenDirect(s);
  ASSERT_TRUE(direct);
  const uint32_t n = static_cast<uint32_t>(s.reader->blocks().size());
  ASSERT_GT(n, 8u);
  ASSERT_NE(s.reader->blocks_file_bytes() % store::kDirectAlign, 0u)
      << "the last block should end unaligned";
  std::vector<BlockRun> runs;
  for (uint32_t i = 0; i < n; ++i) runs.push_back({i, i});
  runs.push_back({0, n - 1});  // larger than any slot's buffer so far: it grows
  runs.push_back({1, n / 2});
  runs.push_back({n / 2, n - 1});
  for (const bool batched : {false, true}) {
    SCOPED_TRACE(batched ? "batched" : "one by one");
    slave::DiskBlockSource disk(*direct, {});
    const int depth = 4;
    std::unique_ptr<AioRuns> aio = disk.OpenAio(depth);
    ASSERT_TRUE(aio) << "this kernel gives no AIO context";
    bool filled = false;
    const auto got = ReadAll(aio.get(), runs, depth, &filled, batched);
    EXPECT_TRUE(filled) << "every slot should have been in flight at some point";
    uint64_t bytes = 0;
    for (size_t r = 0; r < runs.size(); ++r) {
      ASSERT_TRUE(got.at(r).first.ok()) << got.at(r).first.message();
      const std::vector<uint8_t> want = Buffered(*s.reader, runs[r]);
      EXPECT_EQ(got.at(r).second, want) << "blocks " << runs[r].first << " to " << runs[r].last;
      bytes += want.size();
    }
    EXPECT_EQ(disk.reads(), runs.size());
    EXPECT_EQ(disk.bytes_read(), bytes);
  }
}

TEST(AioRuns, InjectedFaultsComeBackAsTheThreadedReadsGiveThem) {
  TestStore s = BuildGenerated("spheres:30000");
  std::unique_ptr<store::StoreReader> direct = OpenDirect(s);
  ASSERT_TRUE(direct);
  slave::FaultOptions faults;
  faults.fail_read = 2;
  faults.corrupt_read = 3;
  for (const bool batched : {false, true}) {
    SCOPED_TRACE(batched ? "batched" : "one by one");
    slave::DiskBlockSource disk(*direct, faults);
    std::unique_ptr<AioRuns> aio = disk.OpenAio(8);
    ASSERT_TRUE(aio);
    const std::vector<BlockRun> runs = {{0, 0}, {1, 1}, {2, 2}, {3, 3}, {4, 4}};
    bool filled = false;
    const auto got = ReadAll(aio.get(), runs, 8, &filled, batched);
    for (size_t r : {0, 1, 4}) {
      ASSERT_TRUE(got.at(r).first.ok()) << got.at(r).first.message();
      EXPECT_EQ(got.at(r).second, Buffered(*s.reader, runs[r]));
    }
    ASSERT_FALSE(got.at(2).first.ok());
    EXPECT_NE(got.at(2).first.message().find("blocks.bin: block 2 at offset"), std::string::npos)
        << got.at(2).first.message();
    ASSERT_TRUE(got.at(3).first.ok());
    const std::vector<uint8_t> clean = Buffered(*s.reader, runs[3]);
    ASSERT_EQ(got.at(3).second.size(), clean.size());
    size_t differ = 0;
    for (size_t i = 0; i < clean.size(); ++i) differ += got.at(3).second[i] != clean[i];
    EXPECT_EQ(differ, 1u);
  }
}

TEST(AioRuns, AFileCutShortWhileOpenIsAnErrorNamingItAndTheOffset) {
  TestStore s = BuildGenerated("spheres:30000");
  std::unique_ptr<store::StoreReader> direct = OpenDirect(s);
  ASSERT_TRUE(direct);
  const uint32_t last = static_cast<uint32_t>(s.reader->blocks().size() - 1);
  const uint64_t offset = s.reader->blocks()[last].offset;
  std::filesystem::resize_file(s.reader->dir() + "/blocks.bin", offset + 10);
  slave::DiskBlockSource disk(*direct, {});
  std::unique_ptr<AioRuns> aio = disk.OpenAio(2);
  ASSERT_TRUE(aio);
  bool filled = false;
  const auto got = ReadAll(aio.get(), {{last, last}}, 2, &filled);
  const Status& status = got.at(0).first;
  ASSERT_FALSE(status.ok());
  // The place: where the file now ends, 10 bytes into the block.
  const std::string where = "blocks.bin: direct read at offset " + std::to_string(offset + 10);
  EXPECT_NE(status.message().find(where), std::string::npos)
      << status.message() << " (the block starts at " << offset << ")";
  EXPECT_NE(status.message().find("unexpected end of file"), std::string::npos) << status.message();
}

TEST(AioRuns, OnlyDirectReadsWithoutAnInjectedLatencyUseIt) {
  TestStore s = BuildGenerated("spheres:3000");
  slave::DiskBlockSource buffered(*s.reader, {});
  EXPECT_FALSE(buffered.OpenAio(4));
  std::unique_ptr<store::StoreReader> direct = OpenDirect(s);
  ASSERT_TRUE(direct);
  slave::FaultOptions slow;
  slow.io_latency_us = 1000;  // slept by a thread per read: the threads' path
  EXPECT_FALSE(slave::DiskBlockSource(*direct, slow).OpenAio(4));
  EXPECT_TRUE(slave::DiskBlockSource(*direct, {}).OpenAio(4));
}

}  // namespace
}  // namespace raystack::testing
