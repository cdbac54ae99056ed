#include "common/image/exr_io.h"

#include <ImfRgbaFile.h>
#include <ImfThreading.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <future>
#include <iterator>
#include <memory>
#include <limits>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "common/base/temp_dir.h"
#include "common/base/thread_cpu.h"

namespace raystack::image {
namespace {

namespace fs = std::filesystem;

// Every layer filled with distinct values, including the ones a lossy or careless path would
// change: +inf (missed pixels), -0, denormals, the largest float, the largest uint32.
ImageLayers TestImage(int width, int height, uint32_t seed) {
  ImageLayers image;
  image.Resize(width, height);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> uniform(-1000, 1000);
  for (float& v : image.rgba) v = uniform(rng);
  for (float& v : image.z) v = std::abs(uniform(rng));
  for (float& v : image.normal) v = uniform(rng);
  for (float& v : image.albedo) v = uniform(rng);
  for (uint32_t& v : image.samples) v = static_cast<uint32_t>(rng());
  for (float& v : image.variance) v = std::abs(uniform(rng)) * 1e-6f;
  image.z[0] = std::numeric_limits<float>::infinity();
  image.z[image.z.size() - 1] = std::numeric_limits<float>::infinity();
  image.rgba[1] = -0.0f;
  image.rgba[2] = std::numeric_limits<float>::denorm_min();
  image.rgba[3] = std::numeric_limits<float>::max();
  image.normal[0] = std::numeric_limits<float>::lowest();
  image.samples[0] = 0xffffffffu;
  image.samples[image.samples.size() - 1] = 0;
  return image;
}

template <typename T>
bool BitEqual(const std::vector<T>& a, const std::vector<T>& b) {
  if (a.size() != b.size()) return false;
  return a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0;
}

// `image` with its colour layer only.
ImageLayers RgbaOnly(ImageLayers image) {
  image.z.clear();
  image.normal.clear();
  image.albedo.clear();
  image.samples.clear();
  image.variance.clear();
  return image;
}

void ExpectBitEqual(const ImageLayers& a, const ImageLayers& b) {
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  EXPECT_TRUE(BitEqual(a.rgba, b.rgba));
  EXPECT_TRUE(BitEqual(a.z, b.z));
  EXPECT_TRUE(BitEqual(a.normal, b.normal));
  EXPECT_TRUE(BitEqual(a.albedo, b.albedo));
  EXPECT_TRUE(BitEqual(a.samples, b.samples));
  EXPECT_TRUE(BitEqual(a.variance, b.variance));
}

void ExpectErrorNaming(const Status& status, const std::string& path,
                       const std::string& what = "") {
  ASSERT_FALSE(status.ok());
  EXPECT_NE(status.message().find(path), std::string::npos) << status.message();
  if (!what.empty()) {
    EXPECT_NE(status.message().find(what), std::string::npos) << status.message();
  }
}

size_t EntryCount(const std::string& folder) {
  return static_cast<size_t>(
      std::distance(fs::directory_iterator(folder), fs::directory_iterator()));
}

TEST(ExrIo, RoundTripIsBitExactForEveryLayer) {
  TempDir dir = TempDir::Create().value();
  // Odd sizes, more rows than one ZIP block (16 scanlines).
  for (auto [w, h] : {std::pair{1, 1}, std::pair{37, 23}, std::pair{64, 40}}) {
    const ImageLayers image = TestImage(w, h, static_cast<uint32_t>(w * 1000 + h));
    const std::string path = dir.File("frame.exr");
    ASSERT_TRUE(WriteExr(path, image).ok());
    Expected<ImageLayers> read = ReadExr(path);
    ASSERT_TRUE(read.ok()) << read.status().message();
    ExpectBitEqual(image, *read);
    EXPECT_TRUE(std::isinf(read->z[0]) && read->z[0] > 0);
  }
  EXPECT_EQ(EntryCount(dir.path()), 1u);  // no temporaries left behind
}

std::string FileBytes(const std::string& path) {
  std::string bytes(static_cast<size_t>(fs::file_size(path)), '\0');
  std::ifstream(path, std::ios::binary).read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  return bytes;
}

// A frame written while the next renders uses the calling thread alone: the file must not
// depend on it. Tall enough for many ZIP chunks (16 rows each), so the pool has work to share.
TEST(ExrIo, EveryCoreAndTheCallingThreadWriteTheSameBytes) {
  TempDir dir = TempDir::Create().value();
  const ImageLayers image = TestImage(64, 200, 7);
  ASSERT_TRUE(WriteExr(dir.File("all.exr"), image, ExrThreads::kAllCores).ok());
  ASSERT_TRUE(WriteExr(dir.File("one.exr"), image, ExrThreads::kCallingThread).ok());
  const std::string all = FileBytes(dir.File("all.exr"));
  EXPECT_GT(all.size(), 1000u);
  EXPECT_TRUE(all == FileBytes(dir.File("one.exr")));
  Expected<ImageLayers> read = ReadExr(dir.File("one.exr"));
  ASSERT_TRUE(read.ok());
  ExpectBitEqual(image, *read);
}

// OpenEXR runs every file's chunks on its process-wide pool once the pool has threads, whatever
// thread writes: a file written "on the calling thread" must really be compressed there (at that
// thread's priority, nice 19 for a frame written while the next renders), not on the pool's
// threads at the job's. An all-core write first starts the pool, as the master's last frame does.
TEST(ExrIo, AFileWrittenOnTheCallingThreadIsCompressedThere) {
  TempDir dir = TempDir::Create().value();
  const ImageLayers image = TestImage(512, 512, 3);
  ASSERT_TRUE(WriteExr(dir.File("all.exr"), image, ExrThreads::kAllCores).ok());
  const double thread_began = ThreadCpuSeconds(), process_began = ProcessCpuSeconds();
  for (int i = 0; i < 3; ++i)
    ASSERT_TRUE(WriteExr(dir.File("one.exr"), image, ExrThreads::kCallingThread).ok());
  const double on_thread = ThreadCpuSeconds() - thread_began;
  const double in_process = ProcessCpuSeconds() - process_began;
  EXPECT_GT(on_thread, 0.0);
  EXPECT_GE(on_thread, 0.9 * in_process)
      << "the calling thread spent " << on_thread << " CPU-s of the process's " << in_process;
  // And an all-core write after it still works (the pool comes back).
  ASSERT_TRUE(WriteExr(dir.File("again.exr"), image, ExrThreads::kAllCores).ok());
  EXPECT_TRUE(FileBytes(dir.File("again.exr")) == FileBytes(dir.File("one.exr")));
}

TEST(ExrIo, OnlyRgbaWritesAndReadsBackTheOthersEmpty) {
  TempDir dir = TempDir::Create().value();
  const ImageLayers image = RgbaOnly(TestImage(8, 4, 1));
  ASSERT_TRUE(WriteExr(dir.File("rgba.exr"), image).ok());
  Expected<ImageLayers> read = ReadExr(dir.File("rgba.exr"));
  ASSERT_TRUE(read.ok()) << read.status().message();
  ExpectBitEqual(image, *read);
}

TEST(ExrIo, ForeignRgbExrWithOffsetWindowReads) {
  TempDir dir = TempDir::Create().value();
  const std::string path = dir.File("foreign.exr");
  // A half-float RGB file whose data window does not start at (0, 0), as other tools write.
  const Imath::Box2i window(Imath::V2i(10, 20), Imath::V2i(13, 22));  // 4 x 3
  std::vector<Imf::Rgba> pixels(12);
  for (size_t i = 0; i < pixels.size(); ++i) pixels[i] = Imf::Rgba(float(i), 0.5f, 2.0f, 1.0f);
  {
    Imf::RgbaOutputFile file(path.c_str(), window, window, Imf::WRITE_RGB);
    file.setFrameBuffer(pixels.data() - 10 - 20 * 4, 1, 4);
    file.writePixels(3);
  }
  Expected<ImageLayers> read = ReadExr(path);
  ASSERT_TRUE(read.ok()) << read.status().message();
  EXPECT_EQ(read->width, 4);
  EXPECT_EQ(read->height, 3);
  ASSERT_EQ(read->rgba.size(), 48u);
  for (size_t i = 0; i < 12; ++i) {
    EXPECT_EQ(read->rgba[4 * i + 0], float(i));
    EXPECT_EQ(read->rgba[4 * i + 1], 0.5f);
    EXPECT_EQ(read->rgba[4 * i + 2], 2.0f);
    EXPECT_EQ(read->rgba[4 * i + 3], 1.0f);  // no alpha in the file: opaque
  }
  EXPECT_TRUE(read->z.empty());
  EXPECT_TRUE(read->normal.empty());
  EXPECT_TRUE(read->samples.empty());
}

// Tall enough to be read in bands of rows on several threads (one per core, 64 rows or more
// each), with a data window that starts below row 0: every band's rows land where they belong.
TEST(ExrIo, ATallImageReadInBandsIsBitExact) {
  TempDir dir = TempDir::Create().value();
  const ImageLayers image = TestImage(45, 517, 17);
  ASSERT_TRUE(WriteExr(dir.File("tall.exr"), image).ok());
  Expected<ImageLayers> read = ReadExr(dir.File("tall.exr"));
  ASSERT_TRUE(read.ok()) << read.status().message();
  ExpectBitEqual(image, *read);

  const std::string path = dir.File("offset.exr");
  const Imath::Box2i window(Imath::V2i(3, 40), Imath::V2i(9, 339));  // 7 x 300
  std::vector<Imf::Rgba> pixels(7 * 300);
  // Row and column in R and G (exact in half floats): a band read into the wrong rows shows.
  for (size_t i = 0; i < pixels.size(); ++i)
    pixels[i] = Imf::Rgba(float(i / 7), float(i % 7), 1.0f, 0.5f);
  {
    Imf::RgbaOutputFile file(path.c_str(), window, window, Imf::WRITE_RGBA);
    file.setFrameBuffer(pixels.data() - 3 - 40 * 7, 1, 7);
    file.writePixels(300);
  }
  read = ReadExr(path);
  ASSERT_TRUE(read.ok()) << read.status().message();
  ASSERT_EQ(read->rgba.size(), 4u * 7 * 300);
  for (size_t i = 0; i < pixels.size(); ++i) {
    ASSERT_EQ(read->rgba[4 * i + 0], float(i / 7)) << i;
    ASSERT_EQ(read->rgba[4 * i + 1], float(i % 7)) << i;
    EXPECT_EQ(read->rgba[4 * i + 3], 0.5f);
  }
}

// Each frame's reference is read into the memory of the frame before's: what the earlier image
// had and the new file lacks must not stay behind.
TEST(ExrIo, ReadingIntoAnEarlierImageLeavesNothingOfIt) {
  TempDir dir = TempDir::Create().value();
  const ImageLayers full = TestImage(40, 30, 5);
  const ImageLayers rgba_only = RgbaOnly(TestImage(20, 70, 6));
  ASSERT_TRUE(WriteExr(dir.File("full.exr"), full).ok());
  ASSERT_TRUE(WriteExr(dir.File("rgba.exr"), rgba_only).ok());
  ImageLayers into;
  ASSERT_TRUE(ReadExrInto(dir.File("full.exr"), &into).ok());
  ExpectBitEqual(full, into);
  ASSERT_TRUE(ReadExrInto(dir.File("rgba.exr"), &into).ok());
  ExpectBitEqual(rgba_only, into);
  ASSERT_TRUE(ReadExrInto(dir.File("full.exr"), &into).ok());
  ExpectBitEqual(full, into);
  ExpectErrorNaming(ReadExrInto(dir.File("missing.exr"), &into), dir.File("missing.exr"));
}

TEST(ExrIo, ReadErrorsNameThePath) {
  TempDir dir = TempDir::Create().value();
  ExpectErrorNaming(ReadExr(dir.File("missing.exr")).status(), dir.File("missing.exr"),
                    "no such file");
  ExpectErrorNaming(ReadExr(dir.path()).status(), dir.path());

  const std::string garbage = dir.File("garbage.exr");
  std::ofstream(garbage, std::ios::binary) << std::string(5000, 'x');
  ExpectErrorNaming(ReadExr(garbage).status(), garbage);
  std::ofstream(dir.File("empty.exr"), std::ios::binary).flush();
  ExpectErrorNaming(ReadExr(dir.File("empty.exr")).status(), dir.File("empty.exr"));

  // A valid file cut short at several places: header, offset table, pixel data.
  const std::string whole = dir.File("whole.exr");
  ASSERT_TRUE(WriteExr(whole, TestImage(64, 64, 3)).ok());
  const auto size = fs::file_size(whole);
  for (double fraction : {0.02, 0.1, 0.5, 0.9, 0.999}) {
    const std::string cut = dir.File("cut.exr");
    fs::copy_file(whole, cut, fs::copy_options::overwrite_existing);
    fs::resize_file(cut, static_cast<uintmax_t>(static_cast<double>(size) * fraction));
    SCOPED_TRACE(fraction);
    ExpectErrorNaming(ReadExr(cut).status(), cut);
  }
}

TEST(ExrIo, WriteErrorsNameThePath) {
  TempDir dir = TempDir::Create().value();
  const ImageLayers image = TestImage(4, 4, 2);
  ExpectErrorNaming(WriteExr(dir.File("no/folder/out.exr"), image), dir.File("no/folder/out.exr"),
                    "does not exist");
  ImageLayers wrong = image;
  wrong.normal.resize(5);
  ExpectErrorNaming(WriteExr(dir.File("out.exr"), wrong), dir.File("out.exr"), "normal");
  ExpectErrorNaming(WriteExr(dir.File("out.exr"), ImageLayers{}), dir.File("out.exr"), "empty");
  ImageLayers no_rgba = image;
  no_rgba.rgba.clear();
  ExpectErrorNaming(WriteExr(dir.File("out.exr"), no_rgba), dir.File("out.exr"), "rgba");
  EXPECT_EQ(EntryCount(dir.path()), 0u);
}

TEST(ExrIo, FailedWriteKeepsThePreviousFile) {
  TempDir dir = TempDir::Create().value();
  const std::string path = dir.File("out.exr");
  const ImageLayers first = TestImage(6, 6, 4);
  ASSERT_TRUE(WriteExr(path, first).ok());
  ImageLayers wrong = TestImage(6, 6, 5);
  wrong.z.resize(1);
  EXPECT_FALSE(WriteExr(path, wrong).ok());
  Expected<ImageLayers> read = ReadExr(path);
  ASSERT_TRUE(read.ok());
  ExpectBitEqual(first, *read);
  // And a good write replaces it.
  const ImageLayers second = TestImage(3, 2, 6);
  ASSERT_TRUE(WriteExr(path, second).ok());
  read = ReadExr(path);
  ASSERT_TRUE(read.ok());
  ExpectBitEqual(second, *read);
}


// Files on the calling thread share OpenEXR's pool (a frame compressed aside and a reference
// read as the next frame starts: neither waits for the other); an all-core file waits until
// they are done, then has the pool at every core.
TEST(ExrPoolLease, FilesOfOneSizeShareThePoolAndAnotherSizeWaits) {
  auto held = std::make_unique<ExrPoolLease>(ExrThreads::kCallingThread);
  EXPECT_EQ(held->threads(), 0);
  std::promise<void> second_taken;
  std::thread second([&] {
    ExrPoolLease again(ExrThreads::kCallingThread);
    second_taken.set_value();
  });
  // A mutex in its place would hold the second one until the first ends.
  EXPECT_EQ(second_taken.get_future().wait_for(std::chrono::seconds(60)),
            std::future_status::ready);
  second.join();

  std::atomic<int> all_core_threads{-1};
  std::thread all_cores([&] {
    ExrPoolLease wide(ExrThreads::kAllCores);
    all_core_threads = Imf::globalThreadCount();
  });
  for (int i = 0; i < 60000 && ExrPoolLease::Waiting() == 0; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  EXPECT_EQ(ExrPoolLease::Waiting(), 1);  // waits while the calling-thread file holds the pool
  EXPECT_EQ(all_core_threads.load(), -1);
  EXPECT_EQ(Imf::globalThreadCount(), 0);
  held.reset();
  all_cores.join();
  EXPECT_EQ(all_core_threads.load(), static_cast<int>(std::max(1u, std::thread::hardware_concurrency())));
}

}  // namespace
}  // namespace raystack::image
