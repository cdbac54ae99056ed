#pragma once
// The whole conversion, as a function: inputs (files or a generated model) -> a block store.
// raystack-prep is a command-line front end to it; tests call it directly.

#include <array>
#include <cstdint>
#include <string>
#include <thread>
#include <vector>

#include "common/base/status.h"
#include "common/base/usable_cores.h"
#include "common/geometry/bvh.h"
#include "tools/import/model_reader.h"

namespace raystack::prep {

// The in-block BVH settings: see tools/bench/RESULTS.md for the measurements behind them.
inline BvhBuildOptions DefaultBlockBvh() {
  BvhBuildOptions o;
  o.max_leaf_size = 8;
  o.traversal_cost = 4.0f;
  o.intersection_cost = 1.0f;
  return o;
}

struct ConvertOptions {
  std::vector<std::string> inputs;  // OBJ/PLY files, merged in order
  std::string generate;             // or a procedural model, "KIND:N" (see generator.h)
  std::string output;               // store directory
  std::string temp_dir;             // "" = $TMPDIR or /tmp
  std::array<int, 3> replicate{1, 1, 1};
  uint32_t target_block_bytes = 32 * 1024;
  uint32_t max_block_bytes = 128 * 1024;
  uint64_t memory_limit_bytes = 1024ull << 20;
  int threads = UsableCores();
  bool threads_given = false;  // --threads (else: the cores), for the messages
  bool shuffle = true;
  BvhBuildOptions bvh = DefaultBlockBvh();  // each block's own BVH
  bool quiet = false;  // no progress output
  // --shift: subtracted from every position read, in double precision (import::PositionShift).
  bool shift = false;
  import::PositionShift shift_by;
};

struct ConvertReport {
  uint64_t source_triangles = 0;  // read, zero-area included
  uint64_t zero_area_dropped = 0;
  uint64_t triangles = 0;  // in the store (after replication)
  uint64_t copies = 1;
  uint64_t blocks = 0, references = 0, raw_bytes = 0, stored_bytes = 0;
  uint32_t largest_raw_bytes = 0, max_depth = 0, partition_passes = 0, multi_block_leaves = 0;
  uint64_t octree_nodes = 0;
  uint64_t emitters = 0;  // emissive triangles listed in lights.bin
  bool shifted = false;   // --shift: positions were shifted by -shift[] (set or automatic)
  double shift[3] = {0, 0, 0};
  double seconds = 0, read_seconds = 0;
};

// Converts; every failure is a Status naming the file and place.
Expected<ConvertReport> Convert(const ConvertOptions& options);

}  // namespace raystack::prep
