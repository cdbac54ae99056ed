// trace_bench: in-core closest-hit throughput through a block store (every block loaded
// first), single thread, for primary rays from a pinhole camera and for random rays. A
// benchmark, not a test: it measures, it asserts nothing.
//   trace_bench STORE [--width W] [--height H] [--random N]

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "common/store/store_reader.h"
#include "common/store/store_tracer.h"

using namespace raystack;

namespace {

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || !std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h")) {
    std::fprintf(argc < 2 ? stderr : stdout,
                 "usage: trace_bench STORE [--width W] [--height H] [--random N]\n"
                 "In-core closest-hit rays/s through a block store, one thread: primary rays of\n"
                 "a W x H pinhole camera (default 1024 x 768) and N random rays (default 1000000).\n");
    return argc < 2 ? 2 : 0;
  }
  int width = 1024, height = 768, random = 1000000;
  for (int i = 2; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--width")) width = std::atoi(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--height")) height = std::atoi(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--random")) random = std::atoi(argv[i + 1]);
  }
  Expected<std::unique_ptr<store::StoreReader>> opened = store::StoreReader::Open(argv[1]);
  if (!opened.ok()) {
    std::fprintf(stderr, "trace_bench: %s\n", opened.status().message().c_str());
    return 1;
  }
  const store::StoreReader& s = **opened;
  store::StoreTracer tracer(s);
  auto start = std::chrono::steady_clock::now();
  if (Status st = tracer.LoadAll(); !st.ok()) {
    std::fprintf(stderr, "trace_bench: %s\n", st.message().c_str());
    return 1;
  }
  std::printf("loaded %zu blocks in %.2f s\n", s.blocks().size(), Seconds(start));

  // Camera: looking at the model's centre from a diagonal, framing its bounding sphere.
  const Bounds3f box = s.model_bounds();
  const Vec3f center = box.Center();
  const float radius = 0.5f * Length(box.Extent());
  const Vec3f eye = center + Normalize(Vec3f{0.6f, 0.5f, 1.0f}) * (radius * 2.2f);
  const Vec3f forward = Normalize(center - eye);
  const Vec3f right = Normalize(Cross(forward, Vec3f{0, 1, 0}));
  const Vec3f up = Cross(right, forward);
  const float tan_half = 0.45f;
  const float aspect = static_cast<float>(width) / static_cast<float>(height);
  uint64_t hits = 0;
  start = std::chrono::steady_clock::now();
  for (int j = 0; j < height; ++j) {
    for (int i = 0; i < width; ++i) {
      const float x = (2 * (static_cast<float>(i) + 0.5f) / static_cast<float>(width) - 1) * tan_half * aspect;
      const float y = (1 - 2 * (static_cast<float>(j) + 0.5f) / static_cast<float>(height)) * tan_half;
      Ray r{eye, forward + right * x + up * y};
      Expected<Hit> h = tracer.Intersect(r);
      hits += h.ok() && h->Valid();
    }
  }
  const double primary = Seconds(start);
  const double n_primary = static_cast<double>(width) * height;
  std::printf("primary  %d x %d: %.3f s, %.2f M rays/s, %.1f%% hit\n", width, height, primary,
              n_primary / primary / 1e6, 100.0 * static_cast<double>(hits) / n_primary);

  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<Ray> rays(static_cast<size_t>(random));
  for (Ray& r : rays) {
    r.origin = center + Vec3f{u(rng), u(rng), u(rng)} * (radius * 0.7f);
    r.direction = Vec3f{u(rng), u(rng), u(rng)};
  }
  hits = 0;
  start = std::chrono::steady_clock::now();
  for (const Ray& r : rays) {
    Expected<Hit> h = tracer.Intersect(r);
    hits += h.ok() && h->Valid();
  }
  const double incoherent = Seconds(start);
  std::printf("random   %d rays: %.3f s, %.2f M rays/s, %.1f%% hit\n", random, incoherent,
              random / incoherent / 1e6, 100.0 * static_cast<double>(hits) / random);
  return 0;
}
