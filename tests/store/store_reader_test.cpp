// A damaged store is an error that names the file and the block, never a crash or a wrong
// image: flipped bytes, truncation, a wrong version, missing files.

#include "common/store/store_reader.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <span>
#include <vector>

#include "common/base/log.h"
#include "common/base/temp_dir.h"
#include "common/store/store_tracer.h"
#include "tools/prep/convert.h"
#include "tests/support/test_dir.h"

namespace raystack::store {
namespace {

class StoreReaderTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = raystack::testing::MakeTestDir();
    ASSERT_TRUE(dir_);
    path_ = dir_->File("store");
    prep::ConvertOptions o;
    o.generate = "sphere:20000";
    o.output = path_;
    o.quiet = true;
    o.target_block_bytes = 8 * 1024;
    Expected<prep::ConvertReport> r = prep::Convert(o);
    ASSERT_TRUE(r.ok()) << r.status().message();
  }

  void FlipByte(const std::string& file, uint64_t offset) {
    std::fstream f(path_ + "/" + file, std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(static_cast<std::streamoff>(offset));
    char c = 0;
    f.read(&c, 1);
    c = static_cast<char>(c ^ 0x10);
    f.seekp(static_cast<std::streamoff>(offset));
    f.write(&c, 1);
  }

  // Lets `edit` change a whole file's body, then re-seals its checksum: the damage a checksum
  // cannot see (a hostile or buggy writer).
  template <typename Edit>
  void EditBody(const std::string& name, Edit&& edit) {
    const std::string file = path_ + "/" + name;
    std::ifstream in(file, std::ios::binary);
    std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), {});
    in.close();
    FileHeader h;
    std::memcpy(&h, bytes.data(), sizeof h);
    std::vector<uint8_t> body(bytes.begin() + sizeof h, bytes.end());
    edit(&body);
    h.body_bytes = body.size();
    h.body_checksum = Checksum(body);
    std::ofstream out(file, std::ios::binary);
    out.write(reinterpret_cast<const char*>(&h), sizeof h);
    out.write(reinterpret_cast<const char*>(body.data()), static_cast<std::streamsize>(body.size()));
  }

  // Lets `edit` change block `id`'s index entry (index.bin re-sealed, and the summary's totals
  // made the blocks' sums again, so that the checks of the entry itself are reached).
  template <typename Edit>
  void EditIndexEntry(uint32_t id, Edit&& edit) {
    EditBody(kIndexFile, [&](std::vector<uint8_t>* body) {
      StoreSummary summary;
      std::memcpy(&summary, body->data(), sizeof summary);
      const size_t first = sizeof summary + summary.material_count * sizeof(MaterialRecord);
      BlockEntry e;
      std::memcpy(&e, body->data() + first + id * sizeof(BlockEntry), sizeof e);
      edit(&e);
      std::memcpy(body->data() + first + id * sizeof(BlockEntry), &e, sizeof e);
      summary.references = summary.raw_bytes = summary.stored_bytes = 0;
      for (uint32_t i = 0; i < summary.block_count; ++i) {
        std::memcpy(&e, body->data() + first + i * sizeof(BlockEntry), sizeof e);
        summary.references += e.triangle_count;
        summary.raw_bytes += e.raw_bytes;
        summary.stored_bytes += e.stored_bytes;
      }
      std::memcpy(body->data(), &summary, sizeof summary);
    });
  }
  // Lets `edit` change index.bin's summary (re-sealed).
  template <typename Edit>
  void EditSummary(Edit&& edit) {
    EditBody(kIndexFile, [&](std::vector<uint8_t>* body) {
      StoreSummary summary;
      std::memcpy(&summary, body->data(), sizeof summary);
      edit(&summary);
      std::memcpy(body->data(), &summary, sizeof summary);
    });
  }

  std::unique_ptr<TempDir> dir_;
  std::string path_;
};

TEST_F(StoreReaderTest, OpensAndEveryBlockVerifies) {
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_TRUE(s.ok()) << s.status().message();
  ASSERT_GT((*s)->blocks().size(), 4u);
  std::vector<uint8_t> stored;
  AlignedBuffer scratch, raw;
  uint64_t references = 0;
  for (uint32_t b = 0; b < (*s)->blocks().size(); ++b) {
    Expected<BlockView> v = (*s)->Load(b, &stored, &scratch, &raw);
    ASSERT_TRUE(v.ok()) << v.status().message();
    references += v->triangle_count();
  }
  EXPECT_EQ(references, (*s)->summary().references);
  EXPECT_GE(references, (*s)->summary().source_triangles);
}

TEST_F(StoreReaderTest, OneFlippedByteInABlockNamesThatBlock) {
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_TRUE(s.ok());
  const uint32_t victim = static_cast<uint32_t>((*s)->blocks().size() / 2);
  const BlockEntry e = (*s)->blocks()[victim];
  s = Expected<std::unique_ptr<StoreReader>>(Status::Error("closed"));
  FlipByte(kBlocksFile, e.offset + e.stored_bytes / 2);

  Expected<std::unique_ptr<StoreReader>> damaged = StoreReader::Open(path_);
  ASSERT_TRUE(damaged.ok());  // the index is intact; the damage shows when the block is read
  std::vector<uint8_t> stored;
  AlignedBuffer scratch, raw;
  for (uint32_t b = 0; b < (*damaged)->blocks().size(); ++b) {
    Expected<BlockView> v = (*damaged)->Load(b, &stored, &scratch, &raw);
    if (b != victim) {
      EXPECT_TRUE(v.ok()) << v.status().message();
      continue;
    }
    ASSERT_FALSE(v.ok());
    const std::string m = v.status().message();
    EXPECT_NE(m.find("block " + std::to_string(victim) + " "), std::string::npos) << m;
    EXPECT_NE(m.find("blocks.bin"), std::string::npos) << m;
  }
  // The tracer reports it too, instead of returning a wrong hit.
  StoreTracer tracer(**damaged);
  EXPECT_FALSE(tracer.LoadAll().ok());
}

TEST_F(StoreReaderTest, DamagedIndexOrOctreeIsRefusedAtOpen) {
  FlipByte(kIndexFile, 200);
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("index.bin"), std::string::npos) << s.status().message();
  FlipByte(kIndexFile, 200);  // repair
  FlipByte(kOctreeFile, 40);
  s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("octree.bin"), std::string::npos) << s.status().message();
}

// A node no walk reaches was never checked: an inner one could name children anywhere, and
// the bounds sweep and the walks' tables visit every node. Open refuses it, naming the file.
TEST_F(StoreReaderTest, AnOctreeNodeOutsideTheTreeIsRefusedAtOpen) {
  EditBody(kOctreeFile, [](std::vector<uint8_t>* body) {
    const OctreeNode stray{1u << 30, 0, kOctreeInner, 0};  // children far out of range
    const auto* p = reinterpret_cast<const uint8_t*>(&stray);
    body->insert(body->end(), p, p + sizeof stray);
  });
  EditBody(kIndexFile, [](std::vector<uint8_t>* body) {
    StoreSummary summary;
    std::memcpy(&summary, body->data(), sizeof summary);
    ++summary.octree_node_count;
    std::memcpy(body->data(), &summary, sizeof summary);
  });
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("octree.bin"), std::string::npos) << s.status().message();
  EXPECT_NE(s.status().message().find("outside the tree"), std::string::npos)
      << s.status().message();
}

// The walks skip a block for rays that miss its bounds in the index, so bounds that are not its
// BVH's would lose hits silently: the block is refused when decoded, naming it.
TEST_F(StoreReaderTest, BoundsThatAreNotTheBlocksBvhAreRefusedNamingTheBlock) {
  const uint32_t victim = 3;
  EditIndexEntry(victim, [](BlockEntry* e) { e->bounds_upper[1] -= 0.25f * (e->bounds_upper[1] - e->bounds_lower[1]); });
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_TRUE(s.ok()) << s.status().message();
  std::vector<uint8_t> stored;
  AlignedBuffer scratch, raw;
  Expected<BlockView> v = (*s)->Load(victim, &stored, &scratch, &raw);
  ASSERT_FALSE(v.ok());
  EXPECT_NE(v.status().message().find("block 3 "), std::string::npos) << v.status().message();
  EXPECT_NE(v.status().message().find("bounds"), std::string::npos) << v.status().message();
  EXPECT_TRUE((*s)->Load(victim + 1, &stored, &scratch, &raw).ok());
}

// An index.bin (and octree.bin) of another, larger store beside this blocks.bin read as "block N
// lies outside the file (truncated?)" (a hostile-input review): the totals say it is a mix.
TEST_F(StoreReaderTest, AnIndexOfAnotherStoreIsSaidToBeOne) {
  prep::ConvertOptions o;
  o.generate = "sphere:60000";
  o.output = dir_->File("larger");
  o.quiet = true;
  o.target_block_bytes = 8 * 1024;
  ASSERT_TRUE(prep::Convert(o).ok());
  for (const char* file : {kIndexFile, kOctreeFile})
    std::filesystem::copy_file(dir_->File(std::string("larger/") + file), path_ + "/" + file,
                               std::filesystem::copy_options::overwrite_existing);
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("the two files are not of one store"), std::string::npos)
      << s.status().message();
}

// A triangle id the store does not have (a forged block's 0xffffffff, the id of no hit, drew a
// black image with exit 0: a hostile-input review) is refused naming the block.
TEST_F(StoreReaderTest, ATriangleIdBeyondTheStoresIsRefusedNamingTheBlock) {
  EditSummary([](StoreSummary* s) { s->source_triangles = 10; });
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_TRUE(s.ok()) << s.status().message();
  std::vector<uint8_t> stored;
  AlignedBuffer scratch, raw;
  Expected<BlockView> v = (*s)->Load(5, &stored, &scratch, &raw);
  ASSERT_FALSE(v.ok());
  EXPECT_NE(v.status().message().find("block 5 "), std::string::npos) << v.status().message();
  EXPECT_NE(v.status().message().find("is beyond the store's 10 triangles"), std::string::npos)
      << v.status().message();
}

TEST_F(StoreReaderTest, NanBoundsAreRefusedAtOpen) {
  EditIndexEntry(2, [](BlockEntry* e) { e->bounds_lower[0] = std::numeric_limits<float>::quiet_NaN(); });
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("index.bin: block 2 has NaN bounds"), std::string::npos)
      << s.status().message();
}

// The loader reads neighbouring blocks as one run and finds each at its offset from the run's
// first: an index whose blocks are out of file order or overlap would make it read outside its
// buffer, so Open refuses it, naming the block.
TEST_F(StoreReaderTest, BlocksOutOfFileOrderAreRefusedAtOpen) {
  uint64_t before = 0;
  {
    Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
    ASSERT_TRUE(s.ok()) << s.status().message();
    before = (*s)->blocks()[3].offset;
  }
  EditIndexEntry(5, [&](BlockEntry* e) { e->offset = before; });
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("blocks.bin: block 5 "), std::string::npos)
      << s.status().message();
  EXPECT_NE(s.status().message().find("overlaps"), std::string::npos) << s.status().message();
}

// Blocks lie back to back: a gap between two (which the loader would read, and allocate, with
// a run of them) or bytes after the last are refused at open, naming where.
TEST_F(StoreReaderTest, GapsBetweenOrAfterBlocksAreRefusedAtOpen) {
  uint32_t last = 0;
  {
    Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
    ASSERT_TRUE(s.ok()) << s.status().message();
    ASSERT_GT((*s)->blocks().size(), 5u);
    last = static_cast<uint32_t>((*s)->blocks().size() - 1);
  }
  EditIndexEntry(4, [](BlockEntry* e) { e->stored_bytes -= 1; });
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("blocks.bin: block 5 "), std::string::npos)
      << s.status().message();
  EXPECT_NE(s.status().message().find("leaves a gap"), std::string::npos) << s.status().message();
  EditIndexEntry(4, [](BlockEntry* e) { e->stored_bytes += 1; });
  ASSERT_TRUE(StoreReader::Open(path_).ok());
  EditIndexEntry(last, [](BlockEntry* e) { e->stored_bytes -= 1; });
  s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("blocks.bin: 1 bytes after the last block"), std::string::npos)
      << s.status().message();
}

// The summary is what raystack-info prints and the renderer sizes by: NaN model bounds, or
// totals that are not the blocks' sums (a forged index: its checksum re-sealed), are refused.
TEST_F(StoreReaderTest, ASummaryThatIsNotItsBlocksIsRefusedAtOpen) {
  EditSummary([](StoreSummary* summary) { summary->model_lower[1] = std::numeric_limits<float>::quiet_NaN(); });
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("index.bin: bad model bounds"), std::string::npos)
      << s.status().message();
  SetUp();
  EditSummary([](StoreSummary* summary) { summary->references += 1000; });
  s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("index.bin: the summary's totals"), std::string::npos)
      << s.status().message();
}

// An offset near 2^64 must not wrap past the file-size test.
TEST_F(StoreReaderTest, AnOffsetThatWouldWrapIsRefusedAtOpen) {
  EditIndexEntry(0, [](BlockEntry* e) { e->offset = ~uint64_t{0} - 7; });
  EditIndexEntry(1, [](BlockEntry* e) { e->offset = ~uint64_t{0} - 3; });
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("block 0 "), std::string::npos) << s.status().message();
  EXPECT_NE(s.status().message().find("outside the file"), std::string::npos)
      << s.status().message();
}

// Buffers and the cache are sized by these: sizes the converter cannot write are refused
// before any block is read.
TEST_F(StoreReaderTest, BlockSizesOutOfRangeAreRefusedAtOpen) {
  const auto expect_refused = [&](uint32_t block) {
    Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.status().message().find(StrFormat("index.bin: block %u has sizes out of range", block)),
              std::string::npos)
        << s.status().message();
  };
  uint32_t cap = 0;
  EditBody(kIndexFile, [&](std::vector<uint8_t>* body) {
    StoreSummary summary;
    std::memcpy(&summary, body->data(), sizeof summary);
    cap = summary.max_block_bytes;
  });
  EditIndexEntry(2, [&](BlockEntry* e) { e->raw_bytes = cap + 4; });
  expect_refused(2);
  SetUp();
  EditIndexEntry(3, [](BlockEntry* e) { e->stored_bytes = 2 * e->raw_bytes + 64; });
  expect_refused(3);
  SetUp();
  EditIndexEntry(4, [](BlockEntry* e) { e->raw_bytes = 8; });
  expect_refused(4);
}

TEST_F(StoreReaderTest, ABlockCapAboveTheFormatsIsRefusedAtOpen) {
  EditBody(kIndexFile, [](std::vector<uint8_t>* body) {
    StoreSummary summary;
    std::memcpy(&summary, body->data(), sizeof summary);
    summary.max_block_bytes = kMaxBlockBytesCap + 1;
    std::memcpy(body->data(), &summary, sizeof summary);
  });
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("index.bin: block size cap"), std::string::npos)
      << s.status().message();
}

// A walk ends early when a ray's hit lies inside the cell of the block it just left, so a
// block whose cell in the index is not its leaf's would lose hits without a word: refused.
TEST_F(StoreReaderTest, ABlockCellThatIsNotItsLeafsIsRefusedAtOpen) {
  EditIndexEntry(3, [](BlockEntry* e) { e->cell_upper[2] += 0.5f * (e->cell_upper[2] - e->cell_lower[2]); });
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("octree.bin: block 3's cell"), std::string::npos)
      << s.status().message();
}

TEST_F(StoreReaderTest, WrongVersionIsNamed) {
  // Each of the store's files says what to do about it.
  for (const char* file : {kIndexFile, kBlocksFile}) {
    SCOPED_TRACE(file);
    FlipByte(file, 8);  // FileHeader::version
    Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.status().message().find("version"), std::string::npos) << s.status().message();
    EXPECT_NE(s.status().message().find("convert the model again"), std::string::npos)
        << s.status().message();
    FlipByte(file, 8);  // back
  }
}

TEST_F(StoreReaderTest, TruncatedBlockFileIsRefused) {
  const std::string blocks = path_ + "/" + kBlocksFile;
  std::filesystem::resize_file(blocks, std::filesystem::file_size(blocks) - 100);
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("truncated"), std::string::npos) << s.status().message();
}

// Found by a converter persona: two bytes appended to blocks.bin were called "truncated?", and
// flipped bytes in its header's size and (unused) checksum fields passed --verify; a flipped
// byte in its body length read as "1099511627776 bytes shorter (truncated?)".
TEST_F(StoreReaderTest, ABlockFileLongerThanItsHeaderOrWithADamagedHeaderIsNamedSo) {
  const std::string blocks = path_ + "/" + kBlocksFile;
  std::filesystem::resize_file(blocks, std::filesystem::file_size(blocks) + 2);
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("2 bytes longer than its header says (appended to?)"),
            std::string::npos) << s.status().message();
  std::filesystem::resize_file(blocks, std::filesystem::file_size(blocks) - 2);
  ASSERT_TRUE(StoreReader::Open(path_).ok());
  // FileHeader::header_bytes, body_bytes' high byte (a file 2^40 bytes "shorter" is whole: the
  // field is damaged, not the file; the day after), body_checksum.
  for (const size_t field : {12u, 21u, 24u}) {
    SCOPED_TRACE(field);
    FlipByte(kBlocksFile, field);
    s = StoreReader::Open(path_);
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.status().message().find("blocks.bin: damaged header"), std::string::npos)
        << s.status().message();
    FlipByte(kBlocksFile, field);  // back
  }
}

TEST_F(StoreReaderTest, MissingStoreIsNamed) {
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_ + "-nope");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("-nope/index.bin"), std::string::npos);
}

TEST_F(StoreReaderTest, EmptyFilesAreRefused) {
  for (const char* file : {kIndexFile, kOctreeFile, kBlocksFile}) {
    SetUp();
    std::filesystem::resize_file(path_ + "/" + file, 0);
    Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
    ASSERT_FALSE(s.ok()) << file;
    EXPECT_NE(s.status().message().find(file), std::string::npos) << s.status().message();
  }
}

// Only regular files are store files: a folder or a FIFO in a file's place is named as such
// (a FIFO used to block the open forever: a hung render), and a store a killed raystack-prep
// left without its index says it is incomplete.
TEST_F(StoreReaderTest, AFolderOrFifoInAFilesPlaceOrAnInterruptedPrepIsNamed) {
  namespace fs = std::filesystem;
  for (const char* file : {kIndexFile, kOctreeFile, kBlocksFile}) {
    SetUp();
    const std::string at = path_ + "/" + file;
    fs::remove(at);
    fs::create_directory(at);
    Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
    ASSERT_FALSE(s.ok()) << file;
    EXPECT_NE(s.status().message().find(at + ": is a folder"), std::string::npos)
        << s.status().message();
    fs::remove(at);
    ASSERT_EQ(mkfifo(at.c_str(), 0600), 0);
    s = StoreReader::Open(path_);  // returns at once (before: blocked in open())
    ASSERT_FALSE(s.ok()) << file;
    EXPECT_NE(s.status().message().find(at + ": is not a regular file"), std::string::npos)
        << s.status().message();
  }
  SetUp();
  fs::rename(path_ + "/" + kBlocksFile, path_ + "/" + kBlocksFile + ".tmp");
  fs::remove(path_ + "/" + kIndexFile);
  Expected<std::unique_ptr<StoreReader>> s = StoreReader::Open(path_);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("the store is incomplete (a raystack-prep was interrupted?)"),
            std::string::npos) << s.status().message();
}

// Direct reads (O_DIRECT) must be aligned to the device's blocks; blocks are not. Every block
// alone, runs of neighbours, and the file's last block (which ends inside an aligned unit)
// come back exactly as buffered reads give them.
TEST_F(StoreReaderTest, DirectReadsGiveTheBufferedBytes) {
  Expected<std::unique_ptr<StoreReader>> buffered = StoreReader::Open(path_);
  Expected<std::unique_ptr<StoreReader>> direct = StoreReader::Open(path_);
  ASSERT_TRUE(buffered.ok() && direct.ok());
  ASSERT_TRUE((*direct)->UseDirectReads().ok());
  EXPECT_TRUE((*direct)->direct_reads());
  EXPECT_FALSE((*buffered)->direct_reads());
  const std::span<const BlockEntry> blocks = (*buffered)->blocks();
  ASSERT_GT(blocks.size(), 8u);
  ASSERT_NE((*buffered)->blocks_file_bytes() % 4096, 0u) << "the last block should end unaligned";
  const auto same = [&](uint32_t first, uint32_t last) {
    const auto [offset, size] = (*buffered)->RunExtent(first, last);
    std::vector<uint8_t> a(size), b(size, 0xee);
    ASSERT_TRUE((*buffered)->ReadRange(offset, size, a.data()).ok());
    const Status s = (*direct)->ReadRange(offset, size, b.data());
    ASSERT_TRUE(s.ok()) << s.message();
    EXPECT_EQ(a, b) << "blocks " << first << " to " << last;
  };
  const uint32_t n = static_cast<uint32_t>(blocks.size());
  for (uint32_t i = 0; i < n; ++i) same(i, i);
  same(0, n - 1);
  same(1, n / 2);
  same(n / 2, n - 1);
  // A range past the end is still an error naming the file.
  std::vector<uint8_t> out(16);
  const Status past = (*direct)->ReadRange((*direct)->blocks_file_bytes() - 8, 16, out.data());
  ASSERT_FALSE(past.ok());
  EXPECT_NE(past.message().find("blocks.bin"), std::string::npos) << past.message();
}

}  // namespace
}  // namespace raystack::store
