#include "tests/geometry/test_meshes.h"

#include <array>
#include <cmath>

namespace raystack::geometry_test {
namespace {

// Position of lattice point (i, j, k) in [0, cells]^3 on the cube surface.
Vec3f LatticePoint(MeshShape shape, int cells, double scale, double translate,
                   std::array<int, 3> ijk) {
  double q[3];
  for (int a = 0; a < 3; ++a) q[a] = 2.0 * ijk[a] / cells - 1.0;
  if (shape == MeshShape::kSphere) {
    const double length = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
    for (double& c : q) c /= length;
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

}  // namespace raystack::geometry_test
