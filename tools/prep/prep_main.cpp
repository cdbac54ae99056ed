// raystack-prep: converts OBJ/PLY models (or a generated one) into a block store, out of core.

#include <fcntl.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "common/base/build_id.h"
#include "common/base/log.h"
#include "common/base/memory_available.h"
#include "common/base/option_number.h"
#include "common/base/output_file.h"
#include "common/base/output_target.h"
#include "common/base/standard_streams.h"
#include "common/base/unknown_option.h"
#include "common/store/format.h"
#include "tools/prep/convert.h"
#include "tools/prep/generator.h"
#include "tools/prep/interrupt_cleanup.h"

namespace raystack::prep {
namespace {

// Writes all of `json` to `fd`, then closes it: "" or why not.
std::string WriteAndClose(int fd, const std::string& json) {
  std::string error;
  for (size_t done = 0; done < json.size() && error.empty();) {
    const ssize_t n = ::write(fd, json.data() + done, json.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) error = n < 0 ? std::strerror(errno) : "no progress";
    else done += static_cast<size_t>(n);
  }
  if (::close(fd) != 0 && error.empty()) error = std::strerror(errno);
  return error;
}

// --stats-json's figures, whole or not at all: a file is written aside and renamed over the
// file the path names (a full disk left a 0-byte file, and /dev/full an exit 0: a pipeline
// review). Written in place: a stream (a pipe, a device, this process's standard output even
// when that is a file: common/base/output_target.h), and a file whose folder takes no new file.
Status WriteStatsJson(const std::string& path, const std::string& json) {
  const auto cannot = [&](const std::string& why) {
    return Status::Error("--stats-json " + path + ": cannot write: " + why);
  };
  const OutputTarget target = ResolveOutputTarget(path);
  if (target.stream) {
    std::fflush(stdout);  // the summary before the figures
    std::string error;
    const int fd = OpenStream(target, &error);
    if (fd < 0) return cannot(error);
    error = WriteAndClose(fd, json);
    return error.empty() ? OkStatus() : cannot(error);
  }
  // A folder that takes no new file, over a file that may still be written (the check before
  // the conversion allowed it): in place.
  std::error_code ec;
  const std::string folder = std::filesystem::path(target.path).parent_path().string();
  if (std::filesystem::exists(target.path, ec) && ::access(folder.empty() ? "." : folder.c_str(), W_OK) != 0) {
    const int fd = ::open(target.path.c_str(), O_WRONLY | O_CLOEXEC | O_TRUNC);
    if (fd < 0) return cannot(std::strerror(errno));
    const std::string error = WriteAndClose(fd, json);
    return error.empty() ? OkStatus() : cannot(error);
  }
  // Aside, then renamed over the file (AtomicOutput: links followed, the link stays).
  Expected<AtomicOutput> out = AtomicOutput::Create(target.path);
  if (!out.ok()) return Status::Error("--stats-json " + out.status().message());
  const std::string temp = out->temp_path();
  const OnInterrupt remove([temp] {  // (an interrupt ends the process without destructors)
    ::unlink(temp.c_str());
    return std::string();
  });
  const int fd = ::open(temp.c_str(), O_WRONLY | O_CLOEXEC | O_TRUNC);
  if (fd < 0) return cannot(std::strerror(errno));
  if (const std::string error = WriteAndClose(fd, json); !error.empty()) return cannot(error);
  if (Status s = out->Commit(); !s.ok()) return Status::Error("--stats-json " + s.message());
  return OkStatus();
}

constexpr const char* kUsage = R"(usage: raystack-prep INPUT... -o STORE [options]
       raystack-prep --generate KIND:N -o STORE [options]

Converts triangle models (OBJ with MTL, PLY ascii/binary) into a raystack block store: a
two-level octree whose leaves are ~32 KB lz4 blocks. Memory stays under --mem-limit whatever
the model's size (the converter spills to temporary files).

options:
  -o, --output DIR        the store directory to write (required)
  --generate KIND:N       a procedural model instead of files: sphere:N, spheres:N, soup:N,
                          cluster:N (about N triangles; 200000 without :N)
  --replicate NX,NY,NZ    repeat the model on a grid (builds huge test models without
                          writing a replicated file first)
  --target-block-kb N     mean raw block size to aim for (default 32)
  --max-block-kb N        hard cap on a raw block (default 128)
  --mem-limit MiB         memory budget of the whole converter (default 1024)
  --threads N             encoding threads (default: the cores it may use)
  --temp-dir DIR          where temporary files go (default: $TMPDIR or /tmp)
  --no-shuffle            plain lz4 without the byte shuffle (for measurement)
  --bvh-leaf N            most triangles per leaf of a block's BVH (default 8)
  --bvh-traversal-cost X  SAH cost of a BVH node relative to a triangle test (default 4)
  --shift auto|X,Y,Z      subtract X,Y,Z (auto: the first vertex, rounded) from every position
                          before it becomes a float: a model far from the origin for its
                          size (a georeferenced scan) keeps its detail; the summary says the
                          shift, and scenes place cameras and lights in the shifted frame
  --stats-json FILE       also write the run's figures as JSON
  --version               this build's version and git commit
  -q, --quiet             no progress or information lines (the summary, warnings and
                          errors stay)
  -h, --help              this text
)";

struct Args {
  ConvertOptions convert;
  std::string stats_json;
};

Status ParseArgs(int argc, char** argv, Args* a, bool* help) {
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    auto value = [&](std::string* out) -> Status {
      if (i + 1 >= argc) return Status::Error(arg + " needs a value");
      *out = argv[++i];
      return OkStatus();
    };
    // `unit` names what the number counts, for the message ("MiB").
    auto number = [&](auto* out, auto lo, auto hi, const char* unit = "") -> Status {
      std::string v;
      RAYSTACK_RETURN_IF_ERROR(value(&v));
      return ParseOptionNumber(arg, v, out, static_cast<double>(lo), static_cast<double>(hi), unit);
    };
    if (arg == "-h" || arg == "--help") {
      *help = true;
      return OkStatus();
    } else if (arg == "-o" || arg == "--output") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->convert.output));
    } else if (arg == "--generate") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->convert.generate));
      if (Expected<GeneratorSpec> g = ParseGeneratorSpec(a->convert.generate); !g.ok())
        return g.status();  // a usage error, before anything runs
    } else if (arg == "--temp-dir") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->convert.temp_dir));
    } else if (arg == "--stats-json") {
      RAYSTACK_RETURN_IF_ERROR(value(&a->stats_json));
    } else if (arg == "--target-block-kb") {
      uint32_t kb = 0;
      RAYSTACK_RETURN_IF_ERROR(number(&kb, 1u, 65536u, "KB"));
      a->convert.target_block_bytes = kb * 1024;
    } else if (arg == "--max-block-kb") {
      uint32_t kb = 0;
      RAYSTACK_RETURN_IF_ERROR(number(&kb, 1u, store::kMaxBlockBytesCap / 1024, "KB"));
      a->convert.max_block_bytes = kb * 1024;
    } else if (arg == "--mem-limit") {
      uint64_t mb = 0;
      RAYSTACK_RETURN_IF_ERROR(number(&mb, uint64_t{64}, uint64_t{1} << 24, "MiB"));
      a->convert.memory_limit_bytes = mb << 20;
    } else if (arg == "--threads") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->convert.threads, 1, 1024));
      a->convert.threads_given = true;
    } else if (arg == "--replicate") {
      std::string v;
      RAYSTACK_RETURN_IF_ERROR(value(&v));
      int end = 0;  // all of it: "2,2,2,2" took 8 copies and dropped the fourth number
      int n = std::sscanf(v.c_str(), "%d,%d,%d%n", &a->convert.replicate[0], &a->convert.replicate[1], &a->convert.replicate[2], &end);
      if (n != 3 || static_cast<size_t>(end) != v.size() || a->convert.replicate[0] < 1 || a->convert.replicate[1] < 1 || a->convert.replicate[2] < 1 ||
          a->convert.replicate[0] > 4096 || a->convert.replicate[1] > 4096 || a->convert.replicate[2] > 4096)
        return Status::Error("--replicate wants NX,NY,NZ with each from 1 to 4096, got '" + v + "'");
    } else if (arg == "--shift") {
      std::string v;
      RAYSTACK_RETURN_IF_ERROR(value(&v));
      a->convert.shift = true;
      import::PositionShift& by = a->convert.shift_by;
      if (v == "auto") {
        by.automatic = true;
      } else {
        int end = 0;
        if (std::sscanf(v.c_str(), "%lf,%lf,%lf%n", &by.by[0], &by.by[1], &by.by[2], &end) != 3 ||
            static_cast<size_t>(end) != v.size() || !std::isfinite(by.by[0]) ||
            !std::isfinite(by.by[1]) || !std::isfinite(by.by[2]))
          return Status::Error("--shift wants auto or X,Y,Z (three numbers), got '" + v + "'");
        by.set = true;
      }
    } else if (arg == "--bvh-leaf") {
      RAYSTACK_RETURN_IF_ERROR(number(&a->convert.bvh.max_leaf_size, 1, 64));
    } else if (arg == "--bvh-traversal-cost") {
      std::string v;
      RAYSTACK_RETURN_IF_ERROR(value(&v));
      char* end = nullptr;
      a->convert.bvh.traversal_cost = std::strtof(v.c_str(), &end);
      if (*end != '\0' || !(a->convert.bvh.traversal_cost > 0.0f) ||
          a->convert.bvh.traversal_cost > 100.0f)
        return Status::Error("--bvh-traversal-cost wants a number in (0, 100], got '" + v + "'");
    } else if (arg == "--no-shuffle") {
      a->convert.shuffle = false;
    } else if (arg == "-q" || arg == "--quiet") {
      a->convert.quiet = true;
    } else if (!arg.empty() && arg[0] == '-') {
      return Status::Error(UnknownOption(arg));
    } else {
      a->convert.inputs.push_back(arg);
    }
  }
  if (a->convert.output.empty()) return Status::Error("no output store given (-o STORE; see --help)");
  if (a->convert.inputs.empty() == a->convert.generate.empty())
    return Status::Error("give input files or --generate KIND:N (not both; see --help)");
  if (a->convert.shift && !a->convert.generate.empty())
    return Status::Error("--shift applies to positions read from files; --generate makes its "
                         "model at the origin");
  if (a->convert.target_block_bytes > a->convert.max_block_bytes)
    return Status::Error(StrFormat("--target-block-kb %u is above --max-block-kb %u",
                                   a->convert.target_block_bytes / 1024,
                                   a->convert.max_block_bytes / 1024));
  return OkStatus();
}

double PeakRssMb() { return static_cast<double>(PeakRssBytes()) / (1 << 20); }

// A budget above what this process may fill (the machine's available memory, or a cgroup
// limit nearer) ends in the kernel's OOM killer, without a word from us: say so first.
void WarnIfBudgetAboveMemory(uint64_t budget) {
  const std::optional<uint64_t> room = MemoryThisProcessMayTake(/*reserve=*/0);
  if (room && budget > *room)
    LOG_WARNING("prep", "--mem-limit %llu MiB is above the %llu MiB this process may fill now (the "
                "memory available, its cgroup's limit or its address-space limit): it may fail "
                "or be killed; give a smaller --mem-limit", static_cast<unsigned long long>(budget >> 20),
                static_cast<unsigned long long>(*room >> 20));
}

int Run(const Args& args) {
  if (args.convert.quiet) SetLogLevel(LogLevel::kWarning);  // -q: as render's, warnings and errors
  WarnIfBudgetAboveMemory(args.convert.memory_limit_bytes);
  if (!args.stats_json.empty()) {  // written at the end: found out now, not after the work
    const std::string parent = std::filesystem::path(args.stats_json).parent_path().string();
    const std::string folder = parent.empty() ? "." : parent;
    // Inside the store it is a file the store does not know: the next conversion into it
    // refused the folder ("holds other files"; a converter persona).
    // Compared as canonical paths without a trailing separator ("out/" is "out").
    const auto canonical = [](const std::string& path, std::error_code* ec) {
      std::filesystem::path p = std::filesystem::weakly_canonical(path, *ec);
      return p.has_filename() ? p : p.parent_path();
    };
    std::error_code folder_ec, stats_ec, store_ec;
    const std::filesystem::path in = canonical(folder, &folder_ec);
    const std::filesystem::path stats = canonical(args.stats_json, &stats_ec);
    const std::filesystem::path store = canonical(args.convert.output, &store_ec);
    if (!store_ec && ((!folder_ec && in == store) || (!stats_ec && stats == store))) {
      std::fprintf(stderr, "raystack-prep: error: --stats-json %s is the store %s or inside it, which "
                   "holds the store's files only: give a path beside it (e.g. %s.json)\n",
                   args.stats_json.c_str(), args.convert.output.c_str(),
                   store.string().c_str());
      return 2;
    }
    // (error_code forms: a link loop threw out of main, exit 134; the day's second review.)
    std::error_code exists_ec;
    const bool exists = std::filesystem::exists(args.stats_json, exists_ec);
    if (exists_ec) {
      std::fprintf(stderr, "raystack-prep: error: --stats-json %s: cannot write it: %s\n",
                   args.stats_json.c_str(), exists_ec.message().c_str());
      return 1;
    }
    // A folder given as the file: found at the end, after the whole conversion (a hostile-input
    // review).
    if (std::filesystem::is_directory(args.stats_json, exists_ec)) {
      std::fprintf(stderr, "raystack-prep: error: --stats-json %s is a folder: give a file (e.g. "
                   "%s)\n", args.stats_json.c_str(),
                   (std::filesystem::path(args.stats_json) / "stats.json").lexically_normal().c_str());
      return 2;
    }
    if (::access(exists ? args.stats_json.c_str() : folder.c_str(), W_OK) != 0) {
      std::fprintf(stderr, "raystack-prep: error: --stats-json %s: cannot write %s: %s\n",
                   args.stats_json.c_str(), exists ? "it" : ("in " + folder).c_str(), std::strerror(errno));
      return 1;
    }
  }
  CleanUpOnInterrupt(args.convert.output);
  Expected<ConvertReport> converted = Convert(args.convert);
  if (!converted.ok()) {
    std::fprintf(stderr, "raystack-prep: error: %s\n", converted.status().message().c_str());
    return 1;
  }
  const ConvertReport& r = *converted;
  const double tris = static_cast<double>(r.triangles);
  const double mtri_s = tris / r.seconds / 1e6;
  std::printf(
      "store %s\n"
      "  triangles      %llu (read %llu, %llu zero-area dropped, x%llu copies)\n"
      "  blocks         %llu, mean raw %.1f KB, largest %.1f KB, %.3f references per triangle\n"
      "  compression    %.2fx (%s), %.1f bytes per triangle on disk\n"
      "  octree         %llu nodes, depth %u, %u partition passes, %u multi-block leaves\n"
      "  time           %.2f s (reading %.2f s), %.2f M triangles/s, peak RSS %.0f MiB\n",
      args.convert.output.c_str(), static_cast<unsigned long long>(r.triangles),
      static_cast<unsigned long long>(r.source_triangles),
      static_cast<unsigned long long>(r.zero_area_dropped),
      static_cast<unsigned long long>(r.copies), static_cast<unsigned long long>(r.blocks),
      r.blocks ? static_cast<double>(r.raw_bytes) / 1024.0 / static_cast<double>(r.blocks) : 0.0,
      r.largest_raw_bytes / 1024.0, static_cast<double>(r.references) / tris,
      r.stored_bytes ? static_cast<double>(r.raw_bytes) / static_cast<double>(r.stored_bytes) : 0.0,
      args.convert.shuffle ? "shuffle+lz4" : "lz4", static_cast<double>(r.stored_bytes) / tris,
      static_cast<unsigned long long>(r.octree_nodes), r.max_depth, r.partition_passes,
      r.multi_block_leaves, r.seconds, r.read_seconds, mtri_s, PeakRssMb());
  if (r.emitters > 0)
    std::printf("  lights         %llu emissive triangles (lights.bin, for path tracing)\n",
                static_cast<unsigned long long>(r.emitters));
  if (r.shifted)
    std::printf("  shift          (%.17g, %.17g, %.17g) subtracted from every position: cameras "
                "and lights go in the shifted frame (their coordinates minus this)\n",
                r.shift[0] + 0.0, r.shift[1] + 0.0, r.shift[2] + 0.0);  // (+ 0.0: no "-0")
  if (!args.stats_json.empty()) {
    const std::string json = StrFormat(
                 "{\"triangles\": %llu, \"zero_area_dropped\": %llu, \"blocks\": %llu, "
                 "\"references\": %llu, \"raw_bytes\": %llu, \"stored_bytes\": %llu, "
                 "\"largest_raw_block_bytes\": %u, \"seconds\": %.3f, \"read_seconds\": %.3f, "
                 "\"mtriangles_per_s\": %.3f, \"peak_rss_mb\": %.1f, \"octree_nodes\": %llu, "
                 "\"max_depth\": %u, \"emitters\": %llu, \"shift\": [%.17g, %.17g, %.17g]}\n",
                 static_cast<unsigned long long>(r.triangles),
                 static_cast<unsigned long long>(r.zero_area_dropped),
                 static_cast<unsigned long long>(r.blocks),
                 static_cast<unsigned long long>(r.references),
                 static_cast<unsigned long long>(r.raw_bytes),
                 static_cast<unsigned long long>(r.stored_bytes), r.largest_raw_bytes, r.seconds,
                 r.read_seconds, mtri_s, PeakRssMb(), static_cast<unsigned long long>(r.octree_nodes),
                 r.max_depth, static_cast<unsigned long long>(r.emitters), r.shift[0], r.shift[1],
                 r.shift[2]);
    if (Status s = WriteStatsJson(args.stats_json, json); !s.ok()) {
      std::fprintf(stderr, "raystack-prep: error: %s (the store is written)\n", s.message().c_str());
      return 1;
    }
  }
  return 0;
}

int Main(int argc, char** argv) {
  if (argc == 1) {  // a first run: what to give, not what is missing
    std::fputs(kUsage, stderr);
    return 2;
  }
  if (argc == 2 && std::strcmp(argv[1], "--version") == 0) {
    std::printf("raystack-prep %s\n", BuildId());
    return 0;
  }
  Args args;
  bool help = false;
  Status s = ParseArgs(argc, argv, &args, &help);
  if (help) {
    std::fputs(kUsage, stdout);
    return 0;
  }
  if (!s.ok()) {
    std::fprintf(stderr, "raystack-prep: %s\n", s.message().c_str());
    return 2;
  }
  return Run(args);
}

}  // namespace
}  // namespace raystack::prep

int main(int argc, char** argv) {
  raystack::OpenClosedStandardStreams();
  return raystack::EndWithStandardOutput("raystack-prep", raystack::prep::Main(argc, argv));
}
