// raystack-prep: converts OBJ/PLY models (or a generated one) into a block store, out of core.

#include <sys/resource.h>

#include <charconv>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "common/base/log.h"
#include "common/base/progress.h"
#include "common/base/temp_dir.h"
#include "common/store/store_writer.h"
#include "tools/import/model_reader.h"
#include "tools/prep/generator.h"
#include "tools/prep/model_source.h"
#include "tools/prep/octree_builder.h"

namespace raystack::prep {
namespace {

constexpr const char* kUsage = R"(usage: raystack-prep INPUT... -o STORE [options]
       raystack-prep --generate KIND:N -o STORE [options]

Converts triangle models (OBJ with MTL, PLY ascii/binary) into a raystack block store: a
two-level octree whose leaves are ~32 KB lz4 blocks. Memory stays under --mem-limit whatever
the model's size (the converter spills to temporary files).

options:
  -o, --output DIR        the store directory to write (required)
  --generate KIND:N       a procedural model instead of files: sphere:N, spheres:N, soup:N,
                          cluster:N (about N triangles)
  --replicate NX,NY,NZ    repeat the model on a grid (builds huge test models without
                          writing a replicated file first)
  --target-block-kb N     mean raw block size to aim for (default 32)
  --max-block-kb N        hard cap on a raw block (default 128)
  --mem-limit MB          memory budget of the whole converter (default 1024)
  --threads N             encoding threads (default: all cores)
  --temp-dir DIR          where temporary files go (default: $TMPDIR or /tmp)
  --no-shuffle            plain lz4 without the byte shuffle (for measurement)
  --stats-json FILE       also write the run's figures as JSON
  -q, --quiet             no progress output
  -h, --help              this text
)";

struct Args {
  std::vector<std::string> inputs;
  std::string output, generate, temp_dir, stats_json;
  std::array<int, 3> replicate{1, 1, 1};
  uint32_t target_kb = 32, max_kb = 128;
  uint64_t mem_limit_mb = 1024;
  int threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  bool shuffle = true, quiet = false;
};

template <typename T>
bool ParseNumber(const std::string& s, T* out) {
  auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), *out);
  return ec == std::errc() && p == s.data() + s.size();
}

Status ParseArgs(int argc, char** argv, Args* a, bool* help) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&](std::string* out) -> Status {
      if (i + 1 >= argc) return Status::Error(arg + " needs a value");
      *out = argv[++i];
      return OkStatus();
    };
    auto number = [&](auto* out, auto lo, auto hi) -> Status {
      std::string v;
      RAYSTACK_RETURN_IF_ERROR(value(&v));
      if (!ParseNumber(v, out) || *out < lo || *out > hi)
        return Status::Error(StrFormat("%s: '%s' is not a number from %lld to %lld", arg.c_str(),
                                       v.c_str(), static_cast<long long>(lo),
                                       static_cast<long long>(hi)));
      return OkStatus();
    };
    if (arg == "-h" || arg == "--help") {
      *help = true;
      return OkStatus();
    } else if (arg == "-o" || arg == "--output") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->output));
    } else if (arg == "--generate") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->generate));
    } else if (arg == "--temp-dir") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->temp_dir));
    } else if (arg == "--stats-json") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->stats_json));
    } else if (arg == "--target-block-kb") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->target_kb, 1u, 65536u));
    } else if (arg == "--max-block-kb") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->max_kb, 1u, 1024u * 1024u));
    } else if (arg == "--mem-limit") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->mem_limit_mb, uint64_t{64}, uint64_t{1} << 24));
    } else if (arg == "--threads") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->threads, 1, 1024));
    } else if (arg == "--replicate") {
      std::string v;
      RAYSTACK_RETURN_IF_ERROR(value(&v));
      int n = std::sscanf(v.c_str(), "%d,%d,%d", &a->replicate[0], &a->replicate[1], &a->replicate[2]);
      if (n != 3 || a->replicate[0] < 1 || a->replicate[1] < 1 || a->replicate[2] < 1 ||
          a->replicate[0] > 4096 || a->replicate[1] > 4096 || a->replicate[2] > 4096)
        return Status::Error("--replicate wants NX,NY,NZ with each from 1 to 4096, got '" + v + "'");
    } else if (arg == "--no-shuffle") {
      a->shuffle = false;
    } else if (arg == "-q" || arg == "--quiet") {
      a->quiet = true;
    } else if (!arg.empty() && arg[0] == '-') {
      return Status::Error("unknown option " + arg + " (see --help)");
    } else {
      a->inputs.push_back(arg);
    }
  }
  if (a->output.empty()) return Status::Error("no output store given (-o STORE; see --help)");
  if (a->inputs.empty() == a->generate.empty())
    return Status::Error("give input files or --generate KIND:N (not both; see --help)");
  if (a->target_kb > a->max_kb)
    return Status::Error(StrFormat("--target-block-kb %u is above --max-block-kb %u", a->target_kb, a->max_kb));
  return OkStatus();
}

double PeakRssMb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

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

int Run(const Args& args) {
  const auto start = std::chrono::steady_clock::now();
  const uint64_t budget = args.mem_limit_mb << 20;
  Expected<TempDir> temp = TempDir::Create(args.temp_dir);
  if (!temp.ok()) {
    LOG_ERROR("prep", "%s", temp.status().message().c_str());
    return 1;
  }

  // 1. Read every input into one spool (RAM up to a fifth of the budget, then disk).
  TriangleSpool spool(temp->File("model.tmp"), budget / 5);
  SpoolSink sink(&spool);
  std::vector<store::MaterialRecord> materials;
  uint64_t source_triangles = 0, zero_area = 0, vertices = 0;
  if (!args.generate.empty()) {
    import::ModelInfo info;
    Status s = GenerateModel(args.generate, sink, &info);
    if (!s.ok()) {
      LOG_ERROR("prep", "%s", s.message().c_str());
      return 1;
    }
    source_triangles += info.triangles;
    zero_area += info.zero_area_dropped;
  }
  for (const std::string& input : args.inputs) {
    std::error_code ec;
    const uint64_t size = std::filesystem::file_size(input, ec);
    ProgressReporter progress("reading " + input, ec ? 0 : size, "B", args.quiet);
    import::ReadOptions options;
    options.vertex_memory_bytes = budget * 3 / 20;
    options.temp_dir = temp->path();
    options.progress = &progress;
    import::ModelInfo info;
    sink.set_material_offset(static_cast<uint32_t>(materials.size()));
    Status s = import::ReadModel(input, options, sink, &info);
    progress.Done();
    if (!s.ok()) {
      LOG_ERROR("prep", "%s", s.message().c_str());
      return 1;
    }
    for (const import::Material& m : info.materials) materials.push_back(ToRecord(m));
    source_triangles += info.triangles;
    zero_area += info.zero_area_dropped;
    vertices += info.vertices;
  }
  if (Status s = spool.Close(); !s.ok()) {
    LOG_ERROR("prep", "%s", s.message().c_str());
    return 1;
  }
  if (materials.size() > store::kMaxMaterials) {
    LOG_ERROR("prep", "%zu materials: format v1 stores at most %u", materials.size(), store::kMaxMaterials);
    return 1;
  }
  const double read_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  ReplicatedSource source(spool, sink.bounds(), sink.has_attributes(), args.replicate);
  if (source.triangles() >= 0xffffffffull) {
    LOG_ERROR("prep", "%llu triangles after replication: format v1 ids are 32-bit",
              static_cast<unsigned long long>(source.triangles()));
    return 1;
  }
  if (source.triangles() == 0) {
    LOG_ERROR("prep", "the model has no triangles (after dropping %llu of zero area)",
              static_cast<unsigned long long>(zero_area));
    return 1;
  }

  // 2. Octree and blocks.
  Expected<std::unique_ptr<store::StoreWriter>> writer = store::StoreWriter::Create(args.output);
  if (!writer.ok()) {
    LOG_ERROR("prep", "%s", writer.status().message().c_str());
    return 1;
  }
  ProgressReporter progress("building blocks", source.triangles(), "tri", args.quiet);
  BuildOptions options;
  options.max_block_bytes = args.max_kb * 1024;
  options.target_block_bytes = args.target_kb * 1024;
  options.memory_bytes = budget * 2 / 5;
  options.threads = args.threads;
  options.temp_dir = temp->path();
  options.shuffle = args.shuffle;
  options.progress = &progress;
  if (vertices > 0 && sink.triangles() > 0)
    options.vertices_per_triangle = std::clamp(
        static_cast<float>(static_cast<double>(vertices) / static_cast<double>(sink.triangles())) * 1.15f,
        0.3f, 3.0f);
  Expected<BuildResult> built = BuildOctree(source, options, writer->get());
  if (!built.ok()) {
    LOG_ERROR("prep", "%s", built.status().message().c_str());
    return 1;
  }
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
  summary.model_flags = (sink.has_attributes() ? store::kModelHasNormals | store::kModelHasUvs : 0) |
                        (materials.empty() ? 0 : store::kModelHasMaterials);
  summary.max_block_bytes = options.max_block_bytes;
  summary.target_block_bytes = options.target_block_bytes;
  summary.codec = args.shuffle ? store::kCodecShuffleLz4 : store::kCodecLz4;
  if (Status s = (*writer)->Finish(summary, built->octree, materials); !s.ok()) {
    LOG_ERROR("prep", "%s", s.message().c_str());
    return 1;
  }

  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const BuildResult& r = *built;
  const double mtri_s = static_cast<double>(source.triangles()) / seconds / 1e6;
  std::printf(
      "store %s\n"
      "  triangles      %llu (read %llu, %llu zero-area dropped, x%llu replicas)\n"
      "  blocks         %llu, mean raw %.1f KB, largest %.1f KB, references %.3f per triangle\n"
      "  compression    %.2fx (%s), %.1f bytes per triangle on disk\n"
      "  octree         %zu nodes, depth %u, %u partition passes, %u multi-block leaves\n"
      "  time           %.2f s (reading %.2f s), %.2f M triangles/s, peak RSS %.0f MB\n",
      args.output.c_str(), static_cast<unsigned long long>(source.triangles()),
      static_cast<unsigned long long>(source_triangles), static_cast<unsigned long long>(zero_area),
      static_cast<unsigned long long>(source.copies()), static_cast<unsigned long long>(r.blocks),
      r.blocks ? r.raw_bytes / 1024.0 / r.blocks : 0.0, r.largest_raw_bytes / 1024.0,
      static_cast<double>(r.references) / source.triangles(),
      r.stored_bytes ? static_cast<double>(r.raw_bytes) / r.stored_bytes : 0.0,
      args.shuffle ? "shuffle+lz4" : "lz4",
      static_cast<double>(r.stored_bytes) / source.triangles(), r.octree.size(), r.max_depth,
      r.partition_passes, r.multi_block_leaves, seconds, read_seconds, mtri_s, PeakRssMb());
  if (!args.stats_json.empty()) {
    std::FILE* f = std::fopen(args.stats_json.c_str(), "w");
    if (!f) {
      LOG_ERROR("prep", "%s: cannot write: %s", args.stats_json.c_str(), std::strerror(errno));
      return 1;
    }
    std::fprintf(f,
                 "{\"triangles\": %llu, \"zero_area_dropped\": %llu, \"blocks\": %llu, "
                 "\"references\": %llu, \"raw_bytes\": %llu, \"stored_bytes\": %llu, "
                 "\"mean_raw_block_bytes\": %.1f, \"largest_raw_block_bytes\": %u, "
                 "\"seconds\": %.3f, \"read_seconds\": %.3f, \"mtriangles_per_s\": %.3f, "
                 "\"peak_rss_mb\": %.1f, \"octree_nodes\": %zu, \"max_depth\": %u}\n",
                 static_cast<unsigned long long>(source.triangles()),
                 static_cast<unsigned long long>(zero_area), static_cast<unsigned long long>(r.blocks),
                 static_cast<unsigned long long>(r.references),
                 static_cast<unsigned long long>(r.raw_bytes),
                 static_cast<unsigned long long>(r.stored_bytes),
                 r.blocks ? static_cast<double>(r.raw_bytes) / r.blocks : 0.0, r.largest_raw_bytes,
                 seconds, read_seconds, mtri_s, PeakRssMb(), r.octree.size(), r.max_depth);
    std::fclose(f);
  }
  return 0;
}

}  // namespace
}  // namespace raystack::prep

int main(int argc, char** argv) {
  raystack::prep::Args args;
  bool help = false;
  raystack::Status s = raystack::prep::ParseArgs(argc, argv, &args, &help);
  if (help) {
    std::fputs(raystack::prep::kUsage, stdout);
    return 0;
  }
  if (!s.ok()) {
    std::fprintf(stderr, "raystack-prep: %s\n", s.message().c_str());
    return 2;
  }
  return raystack::prep::Run(args);
}
