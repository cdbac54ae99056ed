#include "master/preflight.h"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <optional>

#include "common/image/exr_io.h"
#include "common/base/log.h"
#include "common/base/memory_available.h"
#include "common/base/output_file.h"
#include "master/frame_writer.h"

namespace raystack::master {

namespace {

bool SameIgnoringCase(const std::string& a, const char* b) {
  return a.size() == std::strlen(b) &&
         std::equal(a.begin(), a.end(), b, [](char x, char y) {
           return std::tolower(static_cast<unsigned char>(x)) ==
                  std::tolower(static_cast<unsigned char>(y));
         });
}

// `number` with at least `width` digits (leading zeros).
std::string Padded(size_t number, size_t width) {
  std::string digits = std::to_string(number);
  if (digits.size() < width) digits.insert(0, width - digits.size(), '0');
  return digits;
}

// Where the file name (after the last '/') asks for the frame's number: the last run of '#'
// (its length the digits) or a printf-style %d or %0Nd. False if it asks for none.
bool FindFrameField(const std::string& stem, size_t* at, size_t* length, size_t* width) {
  const size_t name = stem.rfind('/') == std::string::npos ? 0 : stem.rfind('/') + 1;
  const size_t hash = stem.find_last_of('#');
  if (hash != std::string::npos && hash >= name) {
    size_t first = hash;
    while (first > name && stem[first - 1] == '#') --first;
    *at = first;
    *length = *width = hash + 1 - first;
    return true;
  }
  for (size_t i = stem.find('%', name); i != std::string::npos; i = stem.find('%', i + 1)) {
    size_t j = i + 1;
    while (j < stem.size() && std::isdigit(static_cast<unsigned char>(stem[j]))) ++j;
    if (j < stem.size() && stem[j] == 'd' && (j == i + 1 || stem[i + 1] == '0')) {
      *at = i;
      *length = j + 1 - i;
      *width = 0;
      for (size_t k = i + 1; k < j; ++k)  // (capped: "%0999999999999999999999d" is no width)
        *width = std::min<size_t>(*width * 10 + static_cast<size_t>(stem[k] - '0'), 1000);
      return true;
    }
  }
  return false;
}

}  // namespace

std::string FramePath(const std::string& path, size_t frame, size_t frames, const char* ext) {
  std::string stem = path, suffix = ext;
  const size_t dot = stem.rfind('.');
  const size_t slash = stem.rfind('/');
  if (dot != std::string::npos && (slash == std::string::npos || dot > slash)) {
    // The user's own spelling of that extension stays (out.EXR is written as out.EXR).
    if (SameIgnoringCase(stem.substr(dot), ext)) suffix = stem.substr(dot);
    stem.resize(dot);
  }
  size_t at = 0, length = 0, width = 0;
  if (frames > 1 && FindFrameField(stem, &at, &length, &width)) {
    stem.replace(at, length, Padded(frame, std::min<size_t>(width, 12)));
  } else if (frames > 1) {
    // As many digits for every frame as the last one has: a sequence's files sort in frame
    // order (frame-10 came before frame-2 for ls, a shell's glob and ffmpeg's glob).
    stem.push_back('-');
    stem.append(Padded(frame, std::to_string(frames - 1).size()));
  }
  stem.append(suffix);
  return stem;
}

Status CheckOutputs(const render::Scene& scene, const std::string& output, bool png,
                    bool checkpoints, FrameRange range) {
  const size_t frames = scene.cameras.size();
  // The output names the EXR: its extension gives way to .exr and .png (and -N per frame when
  // the scene has several cameras), so anything but .exr there, or a folder, is a mistake.
  // With several cameras the path itself is never written (out-0.exr, out-1.exr, ... are), so
  // a folder of that name is in no one's way.
  struct stat st {};
  if ((!output.empty() && output.back() == '/') ||
      (frames == 1 && ::stat(output.c_str(), &st) == 0 && S_ISDIR(st.st_mode)))
    return Status::Error(output + ": is a folder; the output is the EXR file's path (e.g. " +
                         (output.empty() || output.back() == '/' ? output : output + "/") +
                         "image.exr)");
  const size_t dot = output.rfind('.'), slash = output.rfind('/');
  if (dot != std::string::npos && (slash == std::string::npos || dot > slash)) {
    if (dot == slash + 1)  // "dir/.exr": the files would be the hidden .exr and .png
      return Status::Error(output + ": the output needs a name before .exr (e.g. image.exr)");
    if (!SameIgnoringCase(output.substr(dot), ".exr"))
      return Status::Error(output + ": the output is an OpenEXR image; give a path ending in "
                                    ".exr (the PNG quick look goes beside it)");
  }
  // Each frame's images at their largest: 13 uncompressed 32-bit channels in the EXR, 4 bytes a
  // pixel in the PNG; less the files already there that they replace.
  uint64_t all = 0, largest = 0;
  for (size_t f = range.begin; f < range.end; ++f) {
    RAYSTACK_RETURN_IF_ERROR(CheckWritable(FramePath(output, f, frames, ".exr")));
    if (png) RAYSTACK_RETURN_IF_ERROR(CheckWritable(FramePath(output, f, frames, ".png")));
    for (const char* ext : {".exr", ".png"})  // a killed run's, as large as the images
      RemoveStaleTemporaries(FramePath(output, f, frames, ext));
    const uint64_t pixels = static_cast<uint64_t>(scene.cameras[f].width) *
                            static_cast<uint64_t>(scene.cameras[f].height);
    const uint64_t images = pixels * 13 * 4 + (png ? pixels * 4 : 0);
    largest = std::max(largest, images);
    uint64_t there = 0;
    for (const char* ext : {".exr", ".png"}) {
      std::error_code ec;
      const uintmax_t size = std::filesystem::file_size(FramePath(output, f, frames, ext), ec);
      if (!ec) there += size;
    }
    all += images > there ? images - there : 0;
  }
  const std::string first = FramePath(output, range.begin, frames, ".exr");
  const uint64_t temporary = checkpoints ? largest : 0;
  RAYSTACK_RETURN_IF_ERROR(CheckRoom(first, largest + temporary));
  Expected<uint64_t> room = FreeSpace(first);
  if (room.ok() && *room < all + temporary)
    LOG_WARNING("render", "%s: the disk holding it has %.1f MB free; the %zu frames' images take "
                "up to %.1f MB uncompressed (usually far less): if it fills, a frame's write is "
                "tried again for %.0f minutes while space is freed", first.c_str(),
                static_cast<double>(*room) / 1e6, range.end - range.begin,
                static_cast<double>(all + temporary) / 1e6, FrameWriter::kRetrySeconds / 60);
  return OkStatus();
}

Status CheckMemory(const render::Scene& scene, uint64_t cache_bytes, const std::string& what,
                   const std::string& advice) {
  // Measured peaks: 163 bytes a pixel at 2048 x 2048, 208 at 4096 x 4096 (the film's sums 100,
  // the resolved layers 52, the frame being written while the next renders 52).
  constexpr uint64_t kBytesPerPixel = 210;
  uint64_t largest = 0;
  size_t which = 0;
  for (size_t f = 0; f < scene.cameras.size(); ++f) {
    const uint64_t pixels = static_cast<uint64_t>(scene.cameras[f].width) *
                            static_cast<uint64_t>(scene.cameras[f].height);
    if (pixels > largest) largest = pixels, which = f;
  }
  const uint64_t needed = largest * kBytesPerPixel + cache_bytes;
  const std::optional<uint64_t> available = MemoryThisProcessMayTake();
  if (!available || needed <= *available) return OkStatus();
  const render::CameraDesc& c = scene.cameras[which];
  // Megabytes below 10 GB ("0.1 GB needed, 0.1 GB available" said nothing), tenths below 10 MB
  // ("needs about 0 MB" neither).
  const auto size = [](uint64_t bytes) {
    const double mb = static_cast<double>(bytes) / 1e6;
    return mb < 10 ? StrFormat("%.1f MB", mb)
                   : bytes < uint64_t{10} * 1000 * 1000 * 1000 ? StrFormat("%.0f MB", mb)
                                                               : StrFormat("%.1f GB", mb / 1e3);
  };
  // Where the address-space limit is what leaves too little, it is named.
  const std::optional<uint64_t> machine = MemoryAvailable();
  const char* where = machine && *machine > *available ? " under this process's address-space limit "
                                                          "(ulimit -v, less 96 MB for the run)"
                                                        : " here";
  return Status::Error(StrFormat("camera %zu: a %dx%d image needs about %s of memory for its film "
                                 "and images%s; %s is available%s (%s)",
                                 which, c.width, c.height, size(needed).c_str(),
                                 cache_bytes > 0 ? std::string(" and " + what).c_str() : "",
                                 size(*available).c_str(), where,
                                 cache_bytes > 0 ? advice.c_str() : "a smaller image would fit"));
}

EngineMemory EngineMemoryOf(const slave::EngineOptions& engine, const store::StoreReader& store) {
  // Peak of the tree's build: 180 bytes a triangle beyond the blocks (7 M triangles, 1.49 GB of
  // RSS with 0.22 GB of blocks).
  constexpr uint64_t kBvhPeakBytesPerTriangle = 180;
  // What every block costs beside its data, whether it is ever loaded or not (the store's index,
  // the cache's and the loader's entries, each ray thread's queue slot): 240 bytes, and 3.3 more
  // per ray thread (measured: 3,914 and 35,834 blocks, 2 and 32 threads, one block used). A
  // scale review found it outside the check: ~1.3 GB at 3 M blocks (5 billion triangles) and 64
  // threads.
  constexpr uint64_t kBytesPerBlock = 240, kBytesPerBlockPerThread = 4;
  const uint64_t per_block =
      store.blocks().size() * (kBytesPerBlock + kBytesPerBlockPerThread * static_cast<uint64_t>(std::max(engine.threads, 1)));
  const uint64_t decoded = store.summary().raw_bytes;
  EngineMemory m;
  switch (engine.mode) {
    case slave::TraceMode::kBvh:
      m = {decoded + store.summary().references * kBvhPeakBytesPerTriangle,
           "every block and the one BVH over every triangle (--mode bvh)",
           "--mode stack keeps only --cache-mb of blocks"};
      break;
    case slave::TraceMode::kIncore:
      m = {decoded, "every block (--mode incore)", "--mode stack keeps only --cache-mb of blocks"};
      break;
    default:
      m = {std::min(decoded, engine.cache_bytes), "the blocks (--cache-mb)",
           "a smaller --cache-mb would fit"};
  }
  // Where the index outweighs the blocks kept, no --cache-mb helps: said so (a review).
  if (per_block > m.bytes)
    m.advice = StrFormat("the index alone takes %.0f MB: a store of larger blocks (raystack-prep "
                         "--target-block-kb)%s would fit", static_cast<double>(per_block) / 1e6,
                         engine.threads >= 32 ? ", or fewer --threads," : "");
  m.bytes += per_block;
  m.what += StrFormat(" and the index of its %zu blocks", store.blocks().size());
  return m;
}

Status CheckSlaveMemory(const EngineMemory& m, int slaves_here, const std::string& host) {
  const auto mb = [](uint64_t bytes) { return static_cast<double>(bytes) / 1e6; };
  // The machine's memory is shared by its slaves; an address-space limit is each process's own
  // (counted against the machine's total, two slaves each within their own were refused).
  const std::optional<uint64_t> own = MemoryThisProcessMayTake();
  if (own && m.bytes > *own && !(MemoryAvailable() && m.bytes > *MemoryAvailable()))
    return Status::Error(StrFormat("on %s: needs about %.0f MB of memory for %s; its "
                                   "address-space limit (ulimit -v) leaves this process %.0f MB "
                                   "(%s)", host.c_str(), mb(m.bytes), m.what.c_str(), mb(*own),
                                   m.advice.c_str()));
  const std::optional<uint64_t> available = MemoryAvailable();
  const uint64_t needed = m.bytes * static_cast<uint64_t>(std::max(slaves_here, 1));
  if (!available || needed <= *available) return OkStatus();
  const std::string each =
      slaves_here > 1 ? StrFormat(", %.0f MB for each of its %d slaves", mb(m.bytes), slaves_here)
                      : std::string();
  const std::string advice =
      slaves_here > 1 ? m.advice + ", or fewer slaves on this machine" : m.advice;
  return Status::Error(StrFormat("on %s: needs about %.0f MB of memory for %s%s; %.0f MB is "
                                 "available there (%s)", host.c_str(), mb(needed), m.what.c_str(),
                                 each.c_str(), mb(*available), advice.c_str()));
}

Status CheckReferences(const render::Scene& scene, const std::string& reference,
                       FrameRange range) {
  if (reference.empty()) return OkStatus();
  const size_t frames = scene.cameras.size();
  for (size_t f = range.begin; f < range.end; ++f) {
    const std::string path = frames > 1 ? FramePath(reference, f, frames, ".exr") : reference;
    if (::access(path.c_str(), R_OK) != 0)
      return Status::Error(StrFormat("%s: cannot read: %s (--reference of camera %zu)",
                                     path.c_str(), std::strerror(errno), f));
    // Before any frame (a review: frame 0 rendered, then frame 1's checkpoint was refused).
    if (image::IsPartialFrame(path))
      return Status::Error(StrFormat("%s: a checkpoint (its state is partial): a reference is a "
                                     "finished render (--reference of camera %zu)", path.c_str(), f));
  }
  return OkStatus();
}

}  // namespace raystack::master
