#pragma once
// The PLY header: format, and the elements with their properties, in file order. Only the
// header is parsed here; the body is read by ply_reader.cpp. Counts are kept as read and never
// used to allocate: a header may claim anything, the body decides.

#include <cstdint>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "tools/import/buffered_input.h"

namespace raystack::import {

enum class PlyFormat { kAscii, kBinaryLittleEndian, kBinaryBigEndian };

enum class PlyType : uint8_t { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

inline int PlyTypeBytes(PlyType type) {
  constexpr int kBytes[] = {1, 1, 2, 2, 4, 4, 4, 8};
  return kBytes[static_cast<int>(type)];
}
inline bool IsIntegerType(PlyType type) { return type < PlyType::kFloat32; }

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kFloat32;  // of the value, or of each list item
  bool is_list = false;
  PlyType count_type = PlyType::kUint8;  // lists only
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProperty> properties;

  // Index of the property called `name`, or -1.
  int Find(const std::string& property_name) const;
};

struct PlyHeader {
  PlyFormat format = PlyFormat::kAscii;
  std::vector<PlyElement> elements;
};

// Reads from the "ply" line through "end_header", leaving `input` at the first body byte.
// Errors name the file and header line.
Expected<PlyHeader> ReadPlyHeader(BufferedInput& input);

}  // namespace raystack::import
