#include "tools/prep/generator.h"

#include <charconv>
#include <cmath>
#include <random>
#include <vector>

namespace raystack::prep {
namespace {

using import::SourceTriangle;

class Emitter {
 public:
  Emitter(import::TriangleSink& sink, import::ModelInfo* info) : sink_(sink), info_(info) {}
  Status Add(Vec3f a, Vec3f b, Vec3f c) {
    SourceTriangle t;
    t.p[0] = a;
    t.p[1] = b;
    t.p[2] = c;
    ++info_->faces;
    ++info_->triangles;
    if (Cross(b - a, c - a) == Vec3f{0, 0, 0}) {
      ++info_->zero_area_dropped;
      return OkStatus();
    }
    batch_.push_back(t);
    return batch_.size() == 4096 ? Flush() : OkStatus();
  }
  Status Flush() {
    Status s = batch_.empty() ? OkStatus() : sink_.Consume(batch_);
    batch_.clear();
    return s;
  }

 private:
  import::TriangleSink& sink_;
  import::ModelInfo* info_;
  std::vector<SourceTriangle> batch_;
};

// A cube-sphere: each cube face is a k x k grid projected on the sphere. Points come from
// integer lattice coordinates, so an edge shared by two faces has bit-identical vertices and
// the mesh is watertight.
Status CubeSphere(Emitter& out, int k, Vec3f center, float radius) {
  auto point = [&](int a, int b, int c) {
    const Vec3f q{static_cast<float>(a), static_cast<float>(b), static_cast<float>(c)};
    return center + Normalize(q) * radius;
  };
  for (int axis = 0; axis < 3; ++axis) {
    for (int side = -1; side <= 1; side += 2) {
      for (int i = 0; i < k; ++i) {
        for (int j = 0; j < k; ++j) {
          auto at = [&](int u, int v) {
            int c[3];
            c[axis] = side * k;
            c[(axis + 1) % 3] = 2 * u - k;
            c[(axis + 2) % 3] = 2 * v - k;
            return point(c[0], c[1], c[2]);
          };
          const Vec3f p00 = at(i, j), p10 = at(i + 1, j), p01 = at(i, j + 1), p11 = at(i + 1, j + 1);
          if (side > 0) {
            RAYSTACK_RETURN_IF_ERROR(out.Add(p00, p10, p11));
            RAYSTACK_RETURN_IF_ERROR(out.Add(p00, p11, p01));
          } else {
            RAYSTACK_RETURN_IF_ERROR(out.Add(p00, p11, p10));
            RAYSTACK_RETURN_IF_ERROR(out.Add(p00, p01, p11));
          }
        }
      }
    }
  }
  return OkStatus();
}

int SideFor(uint64_t triangles) {  // 12 k^2 triangles per cube-sphere
  return std::max(1, static_cast<int>(std::lround(std::sqrt(static_cast<double>(triangles) / 12.0))));
}

}  // namespace

Expected<GeneratorSpec> ParseGeneratorSpec(const std::string& spec) {
  GeneratorSpec g;
  const size_t colon = spec.find(':');
  g.kind = spec.substr(0, colon);
  if (g.kind != "sphere" && g.kind != "spheres" && g.kind != "soup" && g.kind != "cluster")
    return Status::Error("--generate " + spec +
                         ": unknown kind (use sphere:N, spheres:N, soup:N or cluster:N)");
  if (colon != std::string::npos) {
    const char* begin = spec.data() + colon + 1;
    const char* end = spec.data() + spec.size();
    auto [ptr, ec] = std::from_chars(begin, end, g.n);
    if (ec != std::errc() || ptr != end || g.n == 0 || g.n > 4'000'000'000ull)
      return Status::Error("--generate " + spec + ": N must be a whole number from 1 to 4e9");
  }
  return g;
}

Status GenerateModel(const std::string& spec, import::TriangleSink& sink, import::ModelInfo* info) {
  const Expected<GeneratorSpec> parsed = ParseGeneratorSpec(spec);
  if (!parsed.ok()) return parsed.status();
  const std::string& kind = parsed->kind;
  const uint64_t n = parsed->n;
  *info = import::ModelInfo{};
  Emitter out(sink, info);
  if (kind == "sphere") {
    RAYSTACK_RETURN_IF_ERROR(CubeSphere(out, SideFor(n), {0, 0, 0}, 1.0f));
  } else if (kind == "spheres") {
    const uint64_t floor_tris = std::max<uint64_t>(2, n / 10);
    const int cells = std::max(1, static_cast<int>(std::sqrt(static_cast<double>(floor_tris) / 2)));
    const float half = 5.0f;
    for (int i = 0; i < cells; ++i)
      for (int j = 0; j < cells; ++j) {
        const float x0 = -half + 2 * half * i / cells, x1 = -half + 2 * half * (i + 1) / cells;
        const float z0 = -half + 2 * half * j / cells, z1 = -half + 2 * half * (j + 1) / cells;
        RAYSTACK_RETURN_IF_ERROR(out.Add({x0, 0, z0}, {x0, 0, z1}, {x1, 0, z1}));
        RAYSTACK_RETURN_IF_ERROR(out.Add({x0, 0, z0}, {x1, 0, z1}, {x1, 0, z0}));
      }
    const int k = SideFor((n - std::min(n, floor_tris)) / 16);
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j) {
        const float r = 0.5f + 0.1f * static_cast<float>((i + 2 * j) % 4);
        RAYSTACK_RETURN_IF_ERROR(CubeSphere(out, k, {-3.6f + 2.4f * i, r, -3.6f + 2.4f * j}, r));
      }
  } else {  // soup or cluster (ParseGeneratorSpec knows no other kind)
    std::mt19937_64 rng(12345);
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    const float scale = kind == "soup" ? 1.0f : 1e-6f;
    const float size = kind == "soup" ? 0.05f : 1e-7f;
    for (uint64_t i = 0; i < n; ++i) {
      const Vec3f a{scale * u(rng), scale * u(rng), scale * u(rng)};
      const Vec3f b = a + Vec3f{size * u(rng), size * u(rng), 0};
      const Vec3f c = a + Vec3f{0, size * u(rng), size * u(rng)};
      RAYSTACK_RETURN_IF_ERROR(out.Add(a, b, c));
    }
    info->vertices = 3 * n;  // every triangle its own corners (for the converter's estimates)
    return out.Flush();
  }
  info->vertices = info->triangles / 2;  // closed meshes
  return out.Flush();
}

}  // namespace raystack::prep
