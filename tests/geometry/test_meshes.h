#pragma once
// Closed triangle meshes for watertightness tests, shared by the triangle and BVH tests.

#include <cstdint>
#include <vector>

#include "common/geometry/vec.h"

namespace raystack::geometry_test {

struct Triangle {
  Vec3f p[3];
};

// kScan: the sphere with its radius displaced by bumps and a per-vertex jitter (0.7 to 1.3):
// an irregular, partly concave closed surface, as a scanned model is.
enum class MeshShape { kCube, kSphere, kScan };

// A closed mesh: the surface of [-1, 1]^3 (or the unit sphere projected from it, or the scan) cut into
// `cells` x `cells` squares per face, then scaled and translated (in double, rounded once to
// float). A shared vertex is computed by one function of its lattice point, so its float
// coordinates are the same in every triangle that uses it: the mesh has no cracks in float.
struct ClosedMesh {
  std::vector<Triangle> triangles;
  std::vector<Vec3f> vertices;  // each lattice vertex once
  Vec3f center;                 // rounded translation: strictly inside the mesh
  double scale = 1;
};

ClosedMesh MakeClosedMesh(MeshShape shape, int cells, double scale, double translate);

// Five triangles of the conference room (source ids 74017, 75321, 75406, 76502, 76503) and a
// ray that IntersectTriangle accepts on triangle 3 (76502) although it passes a few ulps outside
// it: the hit, at t = 0x1.ffffe8p-1, lies before the triangle's box, which the ray enters at
// t = 1 as computed, and a farther hit on triangle 0 (t = 0x1.ffffeep-1) prunes that box when
// it is found first. Box tests without a margin miss the closest hit.
struct HitOutsideItsBox {
  Triangle triangles[5];
  uint32_t ids[5];
  Vec3f origin, direction;
};
HitOutsideItsBox ConferenceRoomHitOutsideItsBox();

}  // namespace raystack::geometry_test
