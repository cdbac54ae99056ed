// raystack-info: what a block store holds, and (with --verify) whether every block is sound.

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "common/base/build_id.h"
#include "common/base/log.h"
#include "common/base/progress.h"
#include "common/base/standard_streams.h"
#include "common/base/unknown_option.h"
#include "common/render/material_table.h"
#include "common/store/store_writer.h"
#include "common/store/store_reader.h"
#include "tools/info/image_info.h"

namespace raystack {
namespace {

constexpr const char* kUsage = R"(usage: raystack-info STORE [--verify] [--blocks]
       raystack-info IMAGE.exr

Prints what a raystack block store holds: format version, triangle and reference counts,
blocks and their size histogram, bytes per triangle, compression ratio, bounds, materials.
  --verify   read, checksum, decompress and validate every block (exit 1 if any is bad: the
             first 20 are named, then counted)
  --blocks   list every block (offset, sizes, triangles, cell, bounds)
  --version  this build's version and git commit

Given an EXR that raystack render wrote: its size, its state (complete, or partial: a
checkpoint or what a stopped or failed job kept), its samples per pixel and what rendered it.
Exit 0 only for a complete frame: under mpirun --enable-recovery the job's own exit code is
always 0, so scripts check each image this way.
)";

void PrintHistogram(std::span<const store::BlockEntry> blocks) {
  // Raw sizes in 8 KB bins up to the largest block.
  uint32_t largest = 0;
  for (const auto& b : blocks) largest = std::max(largest, b.raw_bytes);
  constexpr uint32_t kBin = 8 * 1024;
  std::vector<uint64_t> bins(largest / kBin + 1, 0);
  for (const auto& b : blocks) ++bins[b.raw_bytes / kBin];
  const uint64_t most = *std::max_element(bins.begin(), bins.end());
  std::printf("raw block size histogram:\n");
  for (size_t i = 0; i < bins.size(); ++i) {
    const int width = most ? static_cast<int>(50 * bins[i] / most) : 0;
    std::printf("  %4zu-%4zu KB %8llu %s\n", i * 8, i * 8 + 8,
                static_cast<unsigned long long>(bins[i]), std::string(static_cast<size_t>(width), '#').c_str());
  }
}

int Run(const std::string& dir, bool verify, bool list) {
  Expected<std::unique_ptr<store::StoreReader>> opened = store::StoreReader::Open(dir);
  if (!opened.ok()) {
    const std::string none = store::NoStoreThere(dir);
    std::fprintf(stderr, "raystack-info: %s\n",
                 none.empty() ? opened.status().message().c_str() : (dir + ": " + none).c_str());
    return 1;
  }
  const store::StoreReader& s = **opened;
  const store::StoreSummary& m = s.summary();
  const double tris = static_cast<double>(std::max<uint64_t>(m.source_triangles, 1));
  std::printf("store            %s\n", dir.c_str());
  std::printf("format version   %u (codec %s)\n", store::kFormatVersion,
              m.codec == store::kCodecShuffleLz4 ? "byte-shuffle + lz4" : "lz4");
  std::printf("triangles        %llu\n", static_cast<unsigned long long>(m.source_triangles));
  std::printf("references       %llu (%.3f per triangle)\n",
              static_cast<unsigned long long>(m.references), m.references / tris);
  std::printf("blocks           %u (mean raw %.1f KB, mean stored %.1f KB; cap %u KB, target %u KB)\n",
              m.block_count, m.block_count ? m.raw_bytes / 1024.0 / m.block_count : 0.0,
              m.block_count ? m.stored_bytes / 1024.0 / m.block_count : 0.0,
              m.max_block_bytes / 1024, m.target_block_bytes / 1024);
  std::printf("octree nodes     %u\n", m.octree_node_count);
  std::printf("bytes/triangle   %.2f on disk, %.2f raw\n", m.stored_bytes / tris, m.raw_bytes / tris);
  std::printf("compression      %.2fx (%llu -> %llu bytes)\n",
              m.stored_bytes ? static_cast<double>(m.raw_bytes) / m.stored_bytes : 0.0,
              static_cast<unsigned long long>(m.raw_bytes),
              static_cast<unsigned long long>(m.stored_bytes));
  std::printf("model bounds     (%g, %g, %g) - (%g, %g, %g)\n", double{m.model_lower[0]}, double{m.model_lower[1]},
              double{m.model_lower[2]}, double{m.model_upper[0]}, double{m.model_upper[1]}, double{m.model_upper[2]});
  std::printf("root cell        (%g, %g, %g) - (%g, %g, %g)\n", double{m.root_lower[0]}, double{m.root_lower[1]},
              double{m.root_lower[2]}, double{m.root_upper[0]}, double{m.root_upper[1]}, double{m.root_upper[2]});
  std::printf("attributes       %s%s%s\n", (m.model_flags & store::kModelHasNormals) ? "normals " : "",
              (m.model_flags & store::kModelHasUvs) ? "uvs " : "",
              (m.model_flags & store::kModelHasMaterials) ? "materials" : (m.model_flags ? "" : "none"));
  std::printf("materials        %u\n", m.material_count);
  // Each record as stored (illum, d and Ni choose mirror or glass; Ni "none" when the MTL gave
  // none), then what the renderer makes of it (render::MaterialFromMtl) and why, when its illum
  // is not followed: exporters write illums for materials that are not mirrors or glass.
  for (const store::MaterialRecord& r : s.materials()) {
    const std::string ni = r.ni == 0 ? std::string("none") : StrFormat("%.3g", double{r.ni});
    std::printf("  %-24s Kd (%.3g %.3g %.3g) Ks (%.3g %.3g %.3g) Ke (%.3g %.3g %.3g) Ni %s d %.3g "
                "illum %d\n", r.name, double{r.kd[0]}, double{r.kd[1]}, double{r.kd[2]},
                double{r.ks[0]}, double{r.ks[1]}, double{r.ks[2]}, double{r.ke[0]},
                double{r.ke[1]}, double{r.ke[2]}, ni.c_str(), double{r.d}, r.illum);
    std::string note;
    const render::Material as = render::MaterialFromMtl(r, &note);
    const Vec3f a = as.albedo;
    std::printf("  %-24s renders as %s (%.3g %.3g %.3g)%s%s%s\n", "",
                as.type == render::MaterialType::kMirror  ? "a mirror"
                : as.type == render::MaterialType::kGlass ? "glass, tinted"
                                                          : "diffuse",
                double{a.x}, double{a.y}, double{a.z},
                as.type == render::MaterialType::kGlass ? StrFormat(", index %.3g", double{as.ior}).c_str() : "",
                as.emissive() ? ", emits" : "", note.empty() ? "" : (": " + note).c_str());
  }
  if (m.model_flags & store::kModelEmittersUnlisted)
    std::printf("lights           not listed (more emissive triangles than the converter's "
                "--mem-limit held: path tracing does not aim at them)\n");
  else if (s.lights_listed())
    std::printf("lights           %zu emissive triangles (%s)\n", s.emitters().size(),
                store::kLightsFile);
  else
    std::printf("lights           not listed (converted before %s: path tracing does not aim at "
                "its emitters; convert again)\n", store::kLightsFile);
  if (m.block_count) PrintHistogram(s.blocks());
  // A conversion into this store leaves its files aside while it runs, and for good when it is
  // killed (a persona found 345 MB of blocks.bin.tmp beside a store reported complete).
  if (!store::StoreWriter::CheckNotBeingWritten(dir).ok()) {
    std::printf("note             a conversion is writing into this store now: it replaces it "
                "when done\n");
  } else {
    const uint64_t leftover = store::StoreWriter::LeftoverBytes(dir);
    if (leftover > 0)
      std::printf("note             %s of .tmp files beside it, left by an interrupted conversion "
                  "into this store (the next conversion into it removes them; this store is whole)\n",
                  leftover >= 100'000 ? StrFormat("%.1f MB", static_cast<double>(leftover) / 1e6).c_str()
                                      : StrFormat("%llu bytes", static_cast<unsigned long long>(leftover)).c_str());
  }
  if (list) {
    for (uint32_t i = 0; i < s.blocks().size(); ++i) {
      const store::BlockEntry& b = s.blocks()[i];
      std::printf("block %u offset %llu stored %u raw %u triangles %u cell (%g %g %g)-(%g %g %g) "
                  "bounds (%g %g %g)-(%g %g %g)\n", i,
                  static_cast<unsigned long long>(b.offset), b.stored_bytes, b.raw_bytes,
                  b.triangle_count, double{b.cell_lower[0]}, double{b.cell_lower[1]}, double{b.cell_lower[2]},
                  double{b.cell_upper[0]}, double{b.cell_upper[1]}, double{b.cell_upper[2]},
                  double{b.bounds_lower[0]}, double{b.bounds_lower[1]}, double{b.bounds_lower[2]},
                  double{b.bounds_upper[0]}, double{b.bounds_upper[1]}, double{b.bounds_upper[2]});
    }
  }
  if (verify) {
    // Every block, not only up to the first bad one: a store damaged in several places is
    // repaired (or given up) knowing how far the damage goes.
    constexpr uint32_t kNamed = 20;
    std::vector<uint8_t> stored;
    store::AlignedBuffer scratch, raw;
    uint32_t bad = 0;
    {
      ProgressReporter progress("verifying", s.blocks().size(), "blocks");
      for (uint32_t i = 0; i < s.blocks().size(); ++i) {
        Expected<store::BlockView> v = s.Load(i, &stored, &scratch, &raw);
        progress.Update(1);
        if (v.ok()) continue;
        if (++bad <= kNamed) {
          ClearProgressLine();
          std::fprintf(stderr, "raystack-info: %s\n", v.status().message().c_str());
        }
      }
      if (bad > 0) progress.Abandon();
    }
    if (bad > 0) {
      if (bad > kNamed) std::fprintf(stderr, "raystack-info: ... and %u more\n", bad - kNamed);
      std::fprintf(stderr, "raystack-info: %s: %u of %u blocks are damaged (convert the model "
                   "again)\n", dir.c_str(), bad, m.block_count);
      return 1;
    }
    std::printf("verify           all %u blocks OK\n", m.block_count);
  }
  return 0;
}

}  // namespace
}  // namespace raystack

namespace raystack::info {
namespace {

int Main(int argc, char** argv) {
  std::string dir;
  bool verify = false, list = false;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "-h") || !std::strcmp(argv[i], "--help")) {
      std::fputs(raystack::kUsage, stdout);
      return 0;
    }
    if (!std::strcmp(argv[i], "--version")) {
      std::printf("raystack-info %s\n", raystack::BuildId());
      return 0;
    }
    if (!std::strcmp(argv[i], "--verify")) verify = true;
    else if (!std::strcmp(argv[i], "--blocks")) list = true;
    else if (argv[i][0] == '-') {
      std::fprintf(stderr, "raystack-info: %s\n", raystack::UnknownOption(argv[i]).c_str());
      return 2;
    } else if (dir.empty()) dir = argv[i];
    else {
      std::fprintf(stderr, "raystack-info: one store at a time (see --help)\n");
      return 2;
    }
  }
  if (dir.empty()) {
    std::fputs(raystack::kUsage, stderr);
    return 2;
  }
  const bool exr_name = dir.size() > 4 && (dir.compare(dir.size() - 4, 4, ".exr") == 0 ||
                                           dir.compare(dir.size() - 4, 4, ".EXR") == 0);
  // An image: a file (a store is a folder), or a missing one named as an EXR.
  if (std::filesystem::is_regular_file(dir) || (exr_name && !std::filesystem::is_directory(dir))) {
    if (verify || list) {
      std::fprintf(stderr, "raystack-info: --verify and --blocks are for a store (%s is a file)\n",
                   dir.c_str());
      return 2;
    }
    // A file that is not an EXR (a scene file, a model) is neither thing this tool reads: said
    // so, not as an EXR that could not be read (a new user gave it a scene file).
    if (!exr_name && !raystack::info::LooksLikeExr(dir)) {
      std::fprintf(stderr, "raystack-info: %s is neither a block store (a folder made by "
                   "raystack-prep) nor an OpenEXR image\n", dir.c_str());
      return 1;
    }
    return raystack::info::ShowImage(dir);
  }
  return raystack::Run(dir, verify, list);
}

}  // namespace
}  // namespace raystack::info

int main(int argc, char** argv) {
  raystack::OpenClosedStandardStreams();
  return raystack::EndWithStandardOutput("raystack-info", raystack::info::Main(argc, argv));
}
