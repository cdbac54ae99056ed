#pragma once
// Splits an OBJ or PLY face of n >= 3 corners into n - 2 triangles that cover it: a fan from
// its first corner when the face is convex (every quad a scanner writes, so their triangles are
// what they always were), and ear clipping otherwise (an L-shaped face from Blender, SketchUp or
// FreeCAD, whose fan would fill its notch). The face is projected on the plane its Newell normal
// is closest to, in double precision from its first corner. Triangles keep the face's winding.
// Runs of equal corners count once. A face whose projection has no ear left (it crosses itself,
// or has no area) ends as a fan of what is left, as before; so does a non-convex face of more than kMaxClippedCorners corners,
// since ear clipping takes time quadratic in them (the caller says so).
// Not thread-safe; one per reader, reused face to face without allocating.

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "common/geometry/vec.h"

namespace raystack::import {

class PolygonSplitter {
 public:
  static constexpr size_t kMaxClippedCorners = 4096;
  using Triangle = std::array<uint32_t, 3>;  // corner indices into the face

  // The triangles of the face with these corners, in `triangles` (replaced). False when the
  // face is not convex and has more than kMaxClippedCorners corners: it is then split as a fan.
  bool Split(std::span<const Vec3f> corners, std::vector<Triangle>* triangles);

 private:
  bool Project(std::span<const Vec3f> corners);
  bool ProjectedIsConvex() const;
  void ClipEars(bool convex, std::vector<Triangle>* triangles);
  bool IsEar(uint32_t corner) const;

  // The face's corners, each run of equal ones once (indices into the face), projected on its
  // plane, as a ring of the corners not clipped yet; and the corners known to be ears.
  std::vector<uint32_t> ring_;
  std::vector<double> u_, v_;
  std::vector<uint32_t> next_, prev_;
  std::vector<uint8_t> removed_;
  std::vector<uint32_t> ears_;
};

}  // namespace raystack::import
