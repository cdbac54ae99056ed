// Reads models and prints counts, bounds, wall time and peak RSS: a benchmark, not a test.
// Usage: import_bench [--budget BYTES] MODEL...

#include <sys/resource.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "tools/import/model_reader.h"

namespace {

// Touches every triangle so the reader's work cannot be optimised away.
class ChecksumSink : public raystack::import::TriangleSink {
 public:
  raystack::Status Consume(std::span<const raystack::import::SourceTriangle> batch) override {
    for (const auto& t : batch) sum_ += static_cast<double>(t.p[0].x + t.p[1].y + t.p[2].z);
    return raystack::OkStatus();
  }
  double sum() const { return sum_; }

 private:
  double sum_ = 0;
};

}  // namespace

int main(int argc, char** argv) {
  raystack::import::ReadOptions options;
  int first = 1;
  if (argc > 2 && std::string(argv[1]) == "--budget") {
    options.vertex_memory_bytes = std::strtoull(argv[2], nullptr, 10);
    first = 3;
  }
  int failures = 0;
  for (int i = first; i < argc; ++i) {
    ChecksumSink sink;
    raystack::import::ModelInfo info;
    auto start = std::chrono::steady_clock::now();
    raystack::Status status = raystack::import::ReadModel(argv[i], options, sink, &info);
    double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (!status.ok()) {
      std::fprintf(stderr, "%s\n", status.message().c_str());
      ++failures;
      continue;
    }
    rusage usage{};
    getrusage(RUSAGE_SELF, &usage);
    std::printf("%s: %.3f s, %llu vertices, %llu triangles (%llu zero-area), %zu materials, "
                "bounds (%g %g %g)-(%g %g %g), peak RSS %ld MiB, checksum %g\n",
                argv[i], seconds, static_cast<unsigned long long>(info.vertices),
                static_cast<unsigned long long>(info.triangles),
                static_cast<unsigned long long>(info.zero_area_dropped), info.materials.size(),
                static_cast<double>(info.bounds.lower.x), static_cast<double>(info.bounds.lower.y),
                static_cast<double>(info.bounds.lower.z), static_cast<double>(info.bounds.upper.x),
                static_cast<double>(info.bounds.upper.y), static_cast<double>(info.bounds.upper.z),
                usage.ru_maxrss / 1024, sink.sum());
  }
  return failures == 0 ? 0 : 1;
}
