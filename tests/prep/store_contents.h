#pragma once
// Reads a whole (small) store back into memory for the converter tests: every block decoded,
// each triangle's ids and vertices, so tests can state properties of the converter's output.

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/store/store_reader.h"

namespace raystack::prep::testing {

struct StoredTriangle {
  uint32_t id;
  Vec3f p[3];
};

struct StoreContents {
  std::unique_ptr<store::StoreReader> reader;
  std::vector<std::vector<StoredTriangle>> blocks;  // parallel to reader->blocks()
  std::vector<std::vector<uint32_t>> block_ids;     // sorted ids per block
  uint32_t blocks_with_normals = 0;
};

// Opens `dir` and decodes every block; fails the test on any error.
inline void ReadStore(const std::string& dir, StoreContents* out) {
  Expected<std::unique_ptr<store::StoreReader>> opened = store::StoreReader::Open(dir);
  ASSERT_TRUE(opened.ok()) << opened.status().message();
  out->reader = std::move(*opened);
  const store::StoreReader& s = *out->reader;
  out->blocks.assign(s.blocks().size(), {});
  out->block_ids.assign(s.blocks().size(), {});
  std::vector<uint8_t> stored;
  store::AlignedBuffer scratch, raw;
  for (uint32_t b = 0; b < s.blocks().size(); ++b) {
    Expected<store::BlockView> v = s.Load(b, &stored, &scratch, &raw);
    ASSERT_TRUE(v.ok()) << v.status().message();
    ASSERT_EQ(v->triangle_count(), s.blocks()[b].triangle_count);
    out->blocks_with_normals += v->has_normals();
    for (uint32_t t = 0; t < v->triangle_count(); ++t) {
      StoredTriangle st;
      st.id = v->TriangleId(t);
      v->TriangleVertices(t, &st.p[0], &st.p[1], &st.p[2]);
      out->blocks[b].push_back(st);
      out->block_ids[b].push_back(st.id);
    }
    std::sort(out->block_ids[b].begin(), out->block_ids[b].end());
  }
}

// True when the box of `p` meets `cell` widened by a relative tolerance.
inline bool TouchesCell(const Vec3f p[3], const Bounds3f& cell) {
  Bounds3f box;
  for (int i = 0; i < 3; ++i) box.Extend(p[i]);
  const Vec3f e = cell.Extent();
  for (int k = 0; k < 3; ++k) {
    const float pad = 1e-5f * e[k] + 1e-6f * std::max(std::fabs(cell.lower[k]), std::fabs(cell.upper[k]));
    if (box.upper[k] < cell.lower[k] - pad || box.lower[k] > cell.upper[k] + pad) return false;
  }
  return true;
}

}  // namespace raystack::prep::testing
