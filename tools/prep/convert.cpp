#include "tools/prep/convert.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "common/base/log.h"
#include "common/base/progress.h"
#include "common/base/temp_dir.h"
#include "tools/prep/interrupt_cleanup.h"
#include "common/store/store_writer.h"
#include "tools/import/model_reader.h"
#include "tools/prep/disk_room.h"
#include "tools/prep/generator.h"
#include "tools/prep/model_source.h"
#include "tools/prep/octree_builder.h"

namespace raystack::prep {
namespace {

store::MaterialRecord ToRecord(const import::Material& m) {
  store::MaterialRecord r{};
  std::strncpy(r.name, m.name.c_str(), sizeof r.name - 1);
  for (int k = 0; k < 3; ++k) {
    r.kd[k] = m.kd[k];
    r.ks[k] = m.ks[k];
    r.ke[k] = m.ke[k];
  }
  r.ni = m.ni;
  r.d = m.d;
  r.illum = m.illum;
  return r;
}

// The store keeps a material name to sizeof(MaterialRecord::name) - 1 bytes: a longer one is
// cut, and scene overrides then match the cut name, so two names equal after the cut become
// one for the renderer. Say so at conversion, where the MTL file can still be changed.
void WarnAboutCutNames(const std::vector<import::Material>& materials) {
  constexpr size_t kKept = sizeof(store::MaterialRecord::name) - 1;
  std::map<std::string, std::vector<const import::Material*>> by_cut;
  for (const import::Material& m : materials) by_cut[m.name.substr(0, kKept)].push_back(&m);
  for (const import::Material& m : materials) {
    if (m.name.size() <= kKept) continue;
    const char* where = m.defined_at.empty() ? "(no MTL defines it)" : m.defined_at.c_str();
    LOG_WARNING("prep", "%s: material '%s' is %zu bytes long; the store keeps %zu, so it is "
                "stored (and matched by scene overrides) as '%s'", where, m.name.c_str(),
                m.name.size(), kKept, m.name.substr(0, kKept).c_str());
    for (const import::Material* other : by_cut[m.name.substr(0, kKept)])
      if (other != &m && other->name != m.name && (other < &m || other->name.size() <= kKept))
        LOG_WARNING("prep", "%s: materials '%s' and '%s' become one name in the store after the "
                    "cut to %zu bytes (a scene override of one changes both); rename one in the "
                    "MTL file to tell them apart", where, m.name.c_str(), other->name.c_str(),
                    kKept);
  }
}

// Only the materials the faces use go into the store, in the order the sink numbered them (a
// library of 70,000 materials of which a model uses one was refused as too many).
void KeepUsedMaterials(const std::vector<uint32_t>& used, std::vector<store::MaterialRecord>* materials,
                       std::vector<import::Material>* sources) {
  if (used.size() == materials->size() && std::is_sorted(used.begin(), used.end())) return;
  std::vector<store::MaterialRecord> kept;
  std::vector<import::Material> kept_sources;
  for (uint32_t k : used) {
    kept.push_back((*materials)[k]);
    kept_sources.push_back(std::move((*sources)[k]));
  }
  if (kept.size() < materials->size())
    LOG_INFO("prep", "%zu of the model's %zu materials are used by its faces: only those are "
             "stored", kept.size(), materials->size());
  *materials = std::move(kept);
  *sources = std::move(kept_sources);
}

// The reader's own error, found before its progress line starts: a file that cannot be
// opened printed "reading X: 0 B in 0.0 s" before saying so.
Status CheckReadable(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return Status::Error("cannot open " + path + ": " + std::strerror(errno));
  ::close(fd);
  return OkStatus();
}

// The work folder of a conversion that goes on while it is removed (an interrupt): its threads
// delete bucket files as they read them, and remove_all stops at its first error (a file gone
// between listing and removal), which left most of a folder, and gigabytes, behind. So: file by
// file, what is gone already is fine, a few rounds. Returns what could not be removed.
std::string RemoveWhileInUse(const std::string& path) {
  namespace fs = std::filesystem;
  for (int round = 0; round < 5; ++round) {
    std::error_code ec;
    for (fs::directory_iterator it(path, ec), end; !ec && it != end; it.increment(ec)) {
      std::error_code gone;
      fs::remove_all(it->path(), gone);
    }
    fs::remove(path, ec);
    if (!fs::exists(path, ec)) return "";
  }
  return "its work folder " + path + " could not be removed entirely: remove it (or the next "
         "raystack-prep with this --temp-dir will)";
}

double Since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// The triangles of `source` whose material emits, for lights.bin. Held in memory, up to a tenth
// of the converter's budget (2.4 M triangles at the default 1 GB): past that, none are kept and
// a path tracer finds the emitters only where its rays happen to meet them.
// `*too_many`: whether some were found but none kept.
Status CollectEmitters(const TriangleSource& source,
                       std::span<const store::MaterialRecord> materials, uint64_t budget,
                       std::vector<store::EmitterRecord>* emitters, bool* too_many_out) {
  std::vector<uint8_t> emits(materials.size());
  bool any = false;
  for (size_t m = 0; m < materials.size(); ++m) any |= (emits[m] = store::EmitsLight(materials[m]));
  if (!any) return OkStatus();
  const uint64_t most = budget / 10 / sizeof(store::EmitterRecord);
  bool too_many = false;
  RAYSTACK_RETURN_IF_ERROR(source.ForEach(
      [&](std::span<const store::PackedTriangle> tris, std::span<const store::TriangleAttributes>) {
        for (const store::PackedTriangle& t : tris) {
          const uint32_t m = t.material();
          if (m >= emits.size() || !emits[m] || too_many) continue;
          if (emitters->size() >= most) {
            too_many = true;
            continue;
          }
          store::EmitterRecord& e = emitters->emplace_back();
          for (int c = 0; c < 3; ++c)
            for (int a = 0; a < 3; ++a) e.p[c][a] = t.p[c][a];
          e.triangle = t.id;
          e.material = m;
        }
        return OkStatus();
      }));
  if (too_many) {
    LOG_WARNING("prep", "more than %llu emissive triangles (a tenth of --mem-limit): lights.bin "
                "lists none, so path tracing will find the emitters only where its rays meet "
                "them (a larger --mem-limit keeps them)", static_cast<unsigned long long>(most));
    emitters->clear();
    emitters->shrink_to_fit();
  }
  *too_many_out = too_many;
  return OkStatus();
}

// A model far from the origin against its size (georeferenced scans: a 19 cm grid at UTM
// coordinates of 5.4e6 m) loses its detail when its coordinates become floats, whose steps there
// (0.5 m) may be coarser than the model: its triangles fall flat and are dropped, and the
// "zero-area" warning alone sends the user looking in the wrong place. Say what happened.
void WarnAboutFloatSteps(const Bounds3f& bounds) {
  const Vec3f extent = bounds.Extent();
  const float size = std::max(extent.x, std::max(extent.y, extent.z));
  float reach = 0;
  for (int a = 0; a < 3; ++a)
    reach = std::max(reach, std::max(std::fabs(bounds.lower[a]), std::fabs(bounds.upper[a])));
  if (!(size > 0) || !std::isfinite(reach)) return;
  const float step = std::nextafter(reach, INFINITY) - reach;
  constexpr float kFewestSteps = 4096;  // a model at the origin has 2^24 across
  if (size / step >= kFewestSteps) return;
  const Vec3f centre = bounds.Center();
  LOG_WARNING("prep", "the model is %g across but lies %g from the origin, where floats (what "
              "the store keeps) have steps of %g: %.0f steps across it, and detail finer than a "
              "step is lost (flattened triangles are dropped as zero-area). Convert it with "
              "--shift auto (or --shift %.9g,%.9g,%.9g), which moves it near the origin before "
              "its coordinates become floats",
              double{size}, double{reach}, double{step}, double{size / step},
              double{centre.x}, double{centre.y}, double{centre.z});
}

}  // namespace

// The range float ray tracing works in (import::kMaxCoordinate): the readers check each
// vertex; --replicate's copies may reach past it, and a model can be too small as a whole.
Status CheckScale(const Bounds3f& bounds, bool replicated) {
  const Vec3f extent = bounds.Extent();
  const float largest = std::max(extent.x, std::max(extent.y, extent.z));
  for (int a = 0; a < 3; ++a)
    if (!(std::fabs(bounds.lower[a]) <= import::kMaxCoordinate &&
          std::fabs(bounds.upper[a]) <= import::kMaxCoordinate))
      return Status::Error(StrFormat("the model%s reaches %g: beyond +-1e18, where float ray "
                                     "tracing overflows (scale it down)",
                                     replicated ? "'s copies (--replicate)" : "",
                                     static_cast<double>(std::max(std::fabs(bounds.lower[a]),
                                                                  std::fabs(bounds.upper[a])))));
  if (!(largest >= import::kMinExtent))
    return Status::Error(StrFormat("the model is %g across: under %g, float ray tracing underflows "
                                   "(scale it up)", static_cast<double>(largest),
                                   static_cast<double>(import::kMinExtent)));
  return OkStatus();
}

// The builder's size estimates' vertices per triangle, from a model's counts (with the 15%
// margin the conversion has always given it), for the build and for the disk check at a header.
float VerticesPerTriangle(uint64_t vertices, uint64_t triangles) {
  return std::clamp(static_cast<float>(static_cast<double>(vertices) / static_cast<double>(triangles)) * 1.15f,
                    0.3f, 3.0f);
}

// Encoding threads the memory budget has room for: each holds ~150 KB of scratch and its leaf's
// blocks (measured: 512 threads, 78 MB of scratch; 1,024 threads under --mem-limit 64 peaked at
// 262 MB; a converter persona). An eighth of the budget is theirs, at 160 KB and two target
// blocks each; fewer threads than asked (or than the cores, by default) is said.
int ThreadsWithinBudget(int threads, bool given, uint64_t budget, uint32_t target_block_bytes) {
  const uint64_t each = (160 << 10) + 2 * uint64_t{target_block_bytes};
  const int room = static_cast<int>(std::clamp<uint64_t>(budget / 8 / each, 1, 1024));
  if (threads <= room) return threads;
  LOG_WARNING("prep", "%s: --mem-limit %llu leaves room for %d encoding thread%s (each holds "
              "~%llu KB); using %d", given ? StrFormat("--threads %d", threads).c_str()
                                           : StrFormat("%d cores", threads).c_str(),
              static_cast<unsigned long long>(budget >> 20), room, room == 1 ? "" : "s",
              static_cast<unsigned long long>(each >> 10), room);
  return room;
}

Expected<ConvertReport> Convert(const ConvertOptions& args) {
  const auto start = std::chrono::steady_clock::now();
  if (args.output.empty()) return Status::Error("no output store given");
  if (args.inputs.empty() == args.generate.empty())
    return Status::Error("give input files or a model to generate (not both)");
  if (args.target_block_bytes > args.max_block_bytes)
    return Status::Error("the target block size is above the cap");
  RAYSTACK_RETURN_IF_ERROR(store::StoreWriter::CheckNotBeingWritten(args.output));
  RAYSTACK_RETURN_IF_ERROR(store::StoreWriter::CheckFolderIsForAStore(args.output));
  RAYSTACK_RETURN_IF_ERROR(store::StoreWriter::CheckCanWrite(args.output));
  // Every input before the first is read: a typo in the last of several large models was
  // found only after reading the others.
  for (const std::string& input : args.inputs) RAYSTACK_RETURN_IF_ERROR(CheckReadable(input));
  const uint64_t budget = args.memory_limit_bytes;
  int stale = 0;  // work folders of killed preps (their bucket files can be gigabytes)
  Expected<TempDir> temp = TempDir::CreateOwned(args.temp_dir, "raystack-prep", &stale);
  if (!temp.ok()) return temp.status();
  if (stale > 0)
    LOG_INFO("prep", "removed %d work folder%s left by interrupted runs", stale, stale > 1 ? "s" : "");
  const OnInterrupt remove_work([path = temp->path()] { return RemoveWhileInUse(path); });
  ConvertReport report;

  // 1. Read every input into one spool (RAM up to a fifth of the budget, then disk).
  TriangleSpool spool(temp->File("model.tmp"), budget / 5);
  SpoolSink sink(&spool);
  std::vector<store::MaterialRecord> materials;
  std::vector<import::Material> sources;  // the full names, for WarnAboutCutNames
  uint64_t vertices = 0;
  Bounds3f read_bounds;  // of every vertex read
  if (!args.generate.empty()) {
    import::ModelInfo info;
    RAYSTACK_RETURN_IF_ERROR(GenerateModel(args.generate, sink, &info));
    vertices += info.vertices;
    report.source_triangles += info.triangles;
    report.zero_area_dropped += info.zero_area_dropped;
  }
  import::PositionShift shift = args.shift_by;  // one for every file: `automatic` sets it once
  // The disk the conversion will write, checked as soon as a PLY header says how many faces
  // follow (an OBJ: the fewest its size allows) before hours of reading, and again once the
  // model is read: said once.
  const std::string temp_folder = std::filesystem::path(temp->path()).parent_path().string();
  const uint64_t copies = static_cast<uint64_t>(args.replicate[0]) * args.replicate[1] * args.replicate[2];
  bool disk_warned = false;
  auto check_declared = [&](const import::DeclaredModel& declared) {
    const uint64_t read = sink.triangles() + declared.faces;
    // (A model past the store's limit is refused for that, not warned of for its disk.)
    if (disk_warned || read > store::kMaxTriangles / copies) return;
    BuildOptions planned;
    planned.memory_bytes = budget * 2 / 5;
    if (declared.faces > 0) planned.vertices_per_triangle = VerticesPerTriangle(declared.vertices, declared.faces);
    const uint64_t per = SpooledBytesPerTriangle(declared.attributes);
    BuildDiskNeeds needs = EstimateBuildDisk(read * copies, read * copies * per, declared.attributes, planned);
    // The spool, past what it keeps in memory (a fifth of the budget): all of it once spilled.
    if (read * per > budget / 5) needs.spool_bytes = read * per;
    disk_warned = WarnIfDiskMayRunOut(needs, temp_folder, args.output, declared.lower_bound);
  };
  for (const std::string& input : args.inputs) {
    std::error_code ec;
    const uint64_t size = std::filesystem::file_size(input, ec);
    ProgressReporter progress("reading " + input, ec ? 0 : size, "B", args.quiet);
    import::ReadOptions options;
    options.vertex_memory_bytes = budget * 3 / 20;
    options.temp_dir = temp->path();
    options.progress = &progress;
    options.shift = args.shift ? &shift : nullptr;
    options.declared = check_declared;
    // What the store can still take after the files before this one (each file's reader counts
    // from zero).
    options.max_triangles = store::kMaxTriangles - std::min(sink.triangles(), store::kMaxTriangles);
    import::ModelInfo info;
    sink.set_material_offset(static_cast<uint32_t>(materials.size()));
    if (Status read = import::ReadModel(input, options, sink, &info); !read.ok())
      // The sink's own errors (the store's limits) do not know the file: named here.
      return read.message().find(input) == std::string::npos
                 ? Status::Error(input + ": " + read.message())
                 : read;
    progress.Done();
    for (const import::Material& m : info.materials) materials.push_back(ToRecord(m));
    sources.insert(sources.end(), info.materials.begin(), info.materials.end());
    report.source_triangles += info.triangles;
    report.zero_area_dropped += info.zero_area_dropped;
    vertices += info.vertices;
    read_bounds.Extend(info.bounds);
  }
  if (args.shift && shift.set) {
    report.shifted = true;
    for (int a = 0; a < 3; ++a) report.shift[a] = shift.by[a];
  }
  WarnAboutFloatSteps(read_bounds);
  RAYSTACK_RETURN_IF_ERROR(spool.Close());
  KeepUsedMaterials(sink.used_materials(), &materials, &sources);
  WarnAboutCutNames(sources);
  report.read_seconds = Since(start);

  ReplicatedSource source(spool, sink.bounds(), sink.has_attributes(), args.replicate);
  report.triangles = source.triangles();
  report.copies = source.copies();
  // (Copies times triangles checked before it is multiplied: 4096^3 copies would wrap.)
  if (source.copies() > 1 && spool.triangles() > store::kMaxTriangles / source.copies())
    return Status::Error(StrFormat("%llu triangles x %llu copies: a store's triangle ids are 32-bit (at most 4,294,967,294 triangles)",
                                   static_cast<unsigned long long>(spool.triangles()),
                                   static_cast<unsigned long long>(source.copies())));
  if (source.triangles() > store::kMaxTriangles)
    return Status::Error(StrFormat("%llu triangles after replication: a store's triangle ids are 32-bit (at most 4,294,967,294 triangles)",
                                   static_cast<unsigned long long>(source.triangles())));
  if (source.triangles() == 0) {
    std::string names;
    for (const std::string& input : args.inputs) names += (names.empty() ? "" : ", ") + input;
    return Status::Error(StrFormat("%s: no triangles (after dropping %llu of zero area; faces as "
                                   "'f' lines in OBJ, a face element with a vertex index list "
                                   "in PLY)", names.empty() ? "the model" : names.c_str(),
                                   static_cast<unsigned long long>(report.zero_area_dropped)));
  }

  RAYSTACK_RETURN_IF_ERROR(CheckScale(source.bounds(), source.copies() > 1));
  std::vector<store::EmitterRecord> emitters;
  bool unlisted = false;  // emissive triangles, too many to list
  RAYSTACK_RETURN_IF_ERROR(CollectEmitters(source, materials, budget, &emitters, &unlisted));
  report.emitters = emitters.size();

  // 2. Octree and blocks.
  Expected<std::unique_ptr<store::StoreWriter>> writer = store::StoreWriter::Create(args.output);
  if (!writer.ok()) return writer.status();
  const OnInterrupt drop_store([w = writer->get()] {
    w->Abandon();  // after Finish, it leaves the new store (NoteStoreWritten says so)
    return std::string();
  });
  ProgressReporter progress("building blocks", source.triangles(), "tri", args.quiet);
  BuildOptions options;
  options.max_block_bytes = args.max_block_bytes;
  options.target_block_bytes = args.target_block_bytes;
  options.memory_bytes = budget * 2 / 5;
  options.threads = args.threads;
  options.encode_threads = ThreadsWithinBudget(args.threads, args.threads_given, budget,
                                               args.target_block_bytes);
  options.temp_dir = temp->path();
  options.shuffle = args.shuffle;
  options.bvh = args.bvh;
  options.progress = &progress;
  options.quiet = args.quiet;
  if (vertices > 0 && sink.triangles() > 0)
    options.vertices_per_triangle = VerticesPerTriangle(vertices, sink.triangles());
  // (The folder the user chose, or the default: the work folder in it has a random name.)
  if (!disk_warned) WarnIfDiskMayRunOut(EstimateBuildDisk(source, options), temp_folder, args.output);
  Expected<BuildResult> built = BuildOctree(source, options, writer->get());
  if (!built.ok()) return built.status();
  progress.Done();

  store::StoreSummary summary{};
  summary.source_triangles = source.triangles();
  const Bounds3f model = source.bounds();
  for (int a = 0; a < 3; ++a) {
    summary.model_lower[a] = model.lower[a];
    summary.model_upper[a] = model.upper[a];
    summary.root_lower[a] = built->root_cell.lower[a];
    summary.root_upper[a] = built->root_cell.upper[a];
  }
  summary.model_flags = (sink.has_normals() ? uint32_t{store::kModelHasNormals} : 0u) |
                        (sink.has_uvs() ? uint32_t{store::kModelHasUvs} : 0u) |
                        (materials.empty() ? 0u : uint32_t{store::kModelHasMaterials}) |
                        (unlisted ? uint32_t{store::kModelEmittersUnlisted} : 0u);
  summary.max_block_bytes = options.max_block_bytes;
  summary.target_block_bytes = options.target_block_bytes;
  summary.codec = args.shuffle ? store::kCodecShuffleLz4 : store::kCodecLz4;
  RAYSTACK_RETURN_IF_ERROR((*writer)->Finish(summary, built->octree, materials, emitters));
  NoteStoreWritten();

  const BuildResult& r = *built;
  report.blocks = r.blocks;
  report.references = r.references;
  report.raw_bytes = r.raw_bytes;
  report.stored_bytes = r.stored_bytes;
  report.largest_raw_bytes = r.largest_raw_bytes;
  report.max_depth = r.max_depth;
  report.partition_passes = r.partition_passes;
  report.multi_block_leaves = r.multi_block_leaves;
  report.octree_nodes = r.octree.size();
  report.seconds = Since(start);
  return report;
}

}  // namespace raystack::prep
