#include "tools/bench/bench_rays.h"

#include <algorithm>
#include <atomic>
#include <random>
#include <thread>

#include <time.h>

namespace raystack::bench {

Camera FrameModel(const Bounds3f& model) {
  Camera c;
  const Vec3f center = model.Center();
  const float radius = 0.5f * Length(model.Extent());
  c.eye = center + Normalize(Vec3f{0.6f, 0.5f, 1.0f}) * (radius * 1.6f);
  c.forward = Normalize(center - c.eye);
  c.right = Normalize(Cross(c.forward, Vec3f{0, 1, 0}));
  c.up = Cross(c.right, c.forward);
  c.tan_half = 0.4f;
  return c;
}

std::vector<Ray> PrimaryRays(const Camera& c, int width, int height) {
  std::vector<Ray> rays;
  rays.reserve(static_cast<size_t>(width) * static_cast<size_t>(height));
  const float aspect = static_cast<float>(width) / static_cast<float>(height);
  for (int ty = 0; ty < height; ty += 4) {
    for (int tx = 0; tx < width; tx += 4) {
      for (int j = ty; j < ty + 4; ++j) {
        for (int i = tx; i < tx + 4; ++i) {
          const float x = (2 * (static_cast<float>(i) + 0.5f) / static_cast<float>(width) - 1) *
                          c.tan_half * aspect;
          const float y =
              (1 - 2 * (static_cast<float>(j) + 0.5f) / static_cast<float>(height)) * c.tan_half;
          rays.push_back(Ray{c.eye, c.forward + c.right * x + c.up * y});
        }
      }
    }
  }
  return rays;
}

Vec3f LightFor(const Bounds3f& model, const Camera& c) {
  const float radius = 0.5f * Length(model.Extent());
  return model.Center() + c.up * (radius * 1.5f) - c.right * (radius * 0.8f);
}

std::vector<Ray> ShadowRays(std::span<const Ray> primary, std::span<const Hit> hits, Vec3f light) {
  std::vector<Ray> rays;
  for (size_t i = 0; i < primary.size(); ++i) {
    if (!hits[i].Valid()) continue;
    Ray r;
    r.origin = primary[i].origin + primary[i].direction * hits[i].t;
    r.direction = light - r.origin;
    r.tmin = 1e-4f;
    r.tmax = 1.0f - 1e-4f;
    rays.push_back(r);
  }
  return rays;
}

std::vector<Ray> RandomRays(const Bounds3f& model, int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f), d(-1.0f, 1.0f);
  std::vector<Ray> rays(static_cast<size_t>(n));
  const Vec3f e = model.Extent();
  for (Ray& r : rays) {
    r.origin = model.lower + Vec3f{u(rng) * e.x, u(rng) * e.y, u(rng) * e.z};
    r.direction = Vec3f{d(rng), d(rng), d(rng)};
  }
  return rays;
}

void ParallelChunks(int threads, size_t n, size_t chunk,
                    const std::function<void(size_t, size_t, int)>& fn) {
  std::atomic<size_t> next{0};
  auto work = [&](int thread) {
    while (true) {
      const size_t begin = next.fetch_add(chunk);
      if (begin >= n) return;
      fn(begin, std::min(n, begin + chunk), thread);
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(work, t);
  work(0);
  for (std::thread& t : pool) t.join();
}

namespace {

double Now(bool cpu_time) {
  if (!cpu_time) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch())
        .count();
  }
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

}  // namespace

double MedianSeconds(int repeats, const std::function<void()>& fn, bool cpu_time) {
  std::vector<double> times;
  for (int i = 0; i < repeats; ++i) {
    const double start = Now(cpu_time);
    fn();
    times.push_back(Now(cpu_time) - start);
  }
  std::sort(times.begin(), times.end());
  return times[times.size() / 2];
}

}  // namespace raystack::bench
