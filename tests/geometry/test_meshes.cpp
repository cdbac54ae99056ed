#include "tests/geometry/test_meshes.h"

#include <array>
#include <cmath>
#include <cstdint>

namespace raystack::geometry_test {
namespace {

// Position of lattice point (i, j, k) in [0, cells]^3 on the cube surface.
Vec3f LatticePoint(MeshShape shape, int cells, double scale, double translate,
                   std::array<int, 3> ijk) {
  double q[3];
  for (int a = 0; a < 3; ++a) q[a] = 2.0 * ijk[a] / cells - 1.0;
  if (shape != MeshShape::kCube) {
    const double length = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
    double radius = 1;
    if (shape == MeshShape::kScan) {
      // A function of the lattice point only, so shared vertices stay shared.
      uint32_t h = static_cast<uint32_t>(ijk[0] * 73856093 ^ ijk[1] * 19349663 ^ ijk[2] * 83492791);
      h = (h ^ (h >> 13)) * 0x5bd1e995u;
      const double jitter = static_cast<double>(h >> 8) / double{1 << 24} - 0.5;  // [-0.5, 0.5)
      radius = 1 + 0.2 * std::sin(3 * q[0] / length) * std::cos(4 * q[1] / length) + 0.1 * jitter;
    }
    for (double& c : q) c = c / length * radius;
  }
  Vec3f p;
  for (int a = 0; a < 3; ++a) p[a] = static_cast<float>(translate + scale * q[a]);
  return p;
}

}  // namespace

ClosedMesh MakeClosedMesh(MeshShape shape, int cells, double scale, double translate) {
  ClosedMesh mesh;
  mesh.scale = scale;
  const auto c = static_cast<float>(translate);
  mesh.center = {c, c, c};
  auto point = [&](std::array<int, 3> ijk) {
    return LatticePoint(shape, cells, scale, translate, ijk);
  };
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    for (int side = 0; side <= cells; side += cells) {
      for (int i = 0; i < cells; ++i) {
        for (int j = 0; j < cells; ++j) {
          std::array<Vec3f, 4> corner;
          for (int k = 0; k < 4; ++k) {
            std::array<int, 3> ijk{};
            ijk[axis] = side;
            ijk[u] = i + (k == 1 || k == 2 ? 1 : 0);
            ijk[v] = j + (k >= 2 ? 1 : 0);
            corner[k] = point(ijk);
          }
          // Alternate the diagonal so both diagonal directions occur.
          if ((i + j) % 2 == 0) {
            mesh.triangles.push_back({{corner[0], corner[1], corner[2]}});
            mesh.triangles.push_back({{corner[0], corner[2], corner[3]}});
          } else {
            mesh.triangles.push_back({{corner[0], corner[1], corner[3]}});
            mesh.triangles.push_back({{corner[1], corner[2], corner[3]}});
          }
        }
      }
    }
  }
  for (int i = 0; i <= cells; ++i) {
    for (int j = 0; j <= cells; ++j) {
      for (int k = 0; k <= cells; ++k) {
        const bool on_surface = i == 0 || i == cells || j == 0 || j == cells || k == 0 ||
                                k == cells;
        if (on_surface) mesh.vertices.push_back(point({i, j, k}));
      }
    }
  }
  return mesh;
}

HitOutsideItsBox ConferenceRoomHitOutsideItsBox() {
  const float v[5][9] = {
      {0x1.9930fcp+10f, 0x1.b743eap-2f, -0x1.f19c64p+9f, 0x1.992f18p+10f, 0x1.17ba02p-1f,
       -0x1.f1f6c6p+9f, 0x1.993154p+10f, 0x1.b67be6p-2f, -0x1.f19c7p+9f},
      {0x1.992a44p+10f, 0x1.88fc0ep-2f, -0x1.f19ed8p+9f, 0x1.9929f4p+10f, 0x1.88fc0ep-2f,
       -0x1.f19e8ap+9f, 0x1.9929fcp+10f, 0x1.8e43eep-2f, -0x1.f19e76p+9f},
      {0x1.992b2cp+10f, 0x1.96cc1cp-2f, -0x1.f19d34p+9f, 0x1.992b68p+10f, 0x1.930404p-2f,
       -0x1.f19d5ap+9f, 0x1.992b18p+10f, 0x1.96cc1cp-2f, -0x1.f19d8ep+9f},
      {0x1.993154p+10f, 0x1.b6ac22p-2f, -0x1.f19cbep+9f, 0x1.99319cp+10f, 0x1.b43bf8p-2f,
       -0x1.f19cbep+9f, 0x1.99314cp+10f, 0x1.b6ac22p-2f, -0x1.f19cf2p+9f},
      {0x1.99319cp+10f, 0x1.b43bf8p-2f, -0x1.f19cbep+9f, 0x1.993194p+10f, 0x1.b43bf8p-2f,
       -0x1.f19d22p+9f, 0x1.99314cp+10f, 0x1.b6ac22p-2f, -0x1.f19cf2p+9f}};
  HitOutsideItsBox c{{}, {74017, 75321, 75406, 76502, 76503},
                     {0x1.6d32d8p+9f, 0x1.13c728p+9f, -0x1.d4653cp+8f},
                     {0x1.c52fccp+9f, -0x1.139052p+9f, -0x1.076a2ep+9f}};
  for (int i = 0; i < 5; ++i)
    c.triangles[i] = {{{v[i][0], v[i][1], v[i][2]}, {v[i][3], v[i][4], v[i][5]},
                       {v[i][6], v[i][7], v[i][8]}}};
  return c;
}

}  // namespace raystack::geometry_test
