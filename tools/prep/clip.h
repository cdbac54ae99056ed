#pragma once
// Clipping a triangle to an axis-aligned cell: the converter puts a triangle in every cell it
// overlaps and bounds it, inside each, by the box of (triangle ∩ cell), which is much tighter
// than the triangle's own box for the long thin triangles of CAD models.
//
// Conservative by construction: clipping runs in double precision against the cell widened by
// a relative epsilon, and the result is rounded outward to float, so a triangle that touches a
// cell is never dropped from it and its clipped box always contains (triangle ∩ cell).

#include "common/geometry/bounds.h"
#include "common/geometry/vec.h"

namespace raystack::prep {

// The box of triangle (p0, p1, p2) ∩ `cell`, or an empty box when they do not meet.
Bounds3f ClipTriangleToCell(const Vec3f p[3], const Bounds3f& cell);

}  // namespace raystack::prep
