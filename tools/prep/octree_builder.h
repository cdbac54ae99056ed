#pragma once
// Builds the level-1 octree and its blocks from a stream of triangles, out of core.
//
// If the model fits the in-memory budget it is subdivided directly. Otherwise the stream is
// split into 8^k buckets (the cells of octree level k, k <= 3) on disk, each triangle going to
// every cell it overlaps; each bucket is then subdivided in memory (or split again if it is
// still too large). The partition pass reads the stream in pieces on several threads, each
// with its own bucket files, and a bucket is its pieces' files in order: the source's order,
// so the store does not depend on the thread count. Buckets and children are visited in
// Morton order, so blocks reach the disk along a Z-order curve: neighbours in space are
// neighbours in blocks.bin.
//
// Subdivision stops at a cell whose block size estimate is closer (in ratio) to the target
// than its children's mean would be. The cap is never exceeded: the encoding pipeline splits
// any block that comes out above it. A cell that cannot be split (all triangles at one point,
// depth limit, or splits that copy the triangles into every child without separating them,
// as coincident or stacked ones) becomes a leaf with several blocks, and the references stay
// under 4 per source triangle (a partition pass that would pass that stops early), so depth,
// block count and temporary disk stay bounded on degenerate input.

#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/geometry/bounds.h"
#include "common/geometry/bvh.h"
#include "common/store/format.h"
#include "common/store/store_writer.h"
#include "tools/prep/triangle_spool.h"

namespace raystack {
class ProgressReporter;
}

namespace raystack::prep {

struct BuildOptions {
  uint32_t max_block_bytes = 128 * 1024;
  uint32_t target_block_bytes = 32 * 1024;
  uint64_t memory_bytes = 1024ull << 20;  // working set for buckets (a share of --mem-limit)
  int threads = 2;         // the partition pass's readers
  int encode_threads = 0;  // the blocks' encoders (each holds scratch): 0 for `threads`
  std::string temp_dir;
  bool shuffle = true;
  BvhBuildOptions bvh;
  float vertices_per_triangle = 0.6f;  // for size estimates (closed meshes ~0.5, soups 3)
  ProgressReporter* progress = nullptr;  // fed with triangles, each once, as blocks are made
  bool quiet = true;  // no progress of its own (the partition pass's)
};

// A stream of triangles the builder may read several times.
class TriangleSource {
 public:
  virtual ~TriangleSource() = default;
  virtual Status ForEach(const TriangleSpool::Visitor& visit) const = 0;
  virtual uint64_t triangles() const = 0;
  virtual uint64_t bytes() const = 0;  // as spooled
  virtual Bounds3f bounds() const = 0;
  virtual bool has_attributes() const = 0;  // any triangle with normals or uvs
  // The stream cut into contiguous pieces, so the partition pass can read it on several
  // threads: pieces 0, 1, ..., parts - 1 in turn are ForEach's stream, triangle for triangle.
  // `parts` is at most MaxParts() (1 for a source that cannot be cut).
  virtual int MaxParts() const { return 1; }
  virtual Status ForEachPart(int part, int parts, const TriangleSpool::Visitor& visit) const {
    return parts == 1 && part == 0 ? ForEach(visit) : Status::Error("this source cannot be cut");
  }
};

struct BuildResult {
  std::vector<store::OctreeNode> octree;
  Bounds3f root_cell;
  uint64_t references = 0, blocks = 0, raw_bytes = 0, stored_bytes = 0, cap_splits = 0;
  uint32_t largest_raw_bytes = 0, max_depth = 0, multi_block_leaves = 0, partition_passes = 0;
};

// Builds into an open StoreWriter (the caller finishes the store with the returned octree).
Expected<BuildResult> BuildOctree(const TriangleSource& source, const BuildOptions& options,
                                  store::StoreWriter* writer);

// Disk the build will likely write: bucket files in options.temp_dir (none when the model is
// built in memory) and the store's blocks. Estimates (the store's bytes depend on how well its
// blocks compress), for a check of the free space before hours of work.
struct BuildDiskNeeds {
  uint64_t spool_bytes = 0;  // the model as read, still to be written (kept to the end)
  uint64_t temp_bytes = 0;   // bucket files at their peak (deleted as the store is written)
  uint64_t store_bytes = 0;
};
BuildDiskNeeds EstimateBuildDisk(const TriangleSource& source, const BuildOptions& options);
// The same before the model is read: `triangles`, spooled in `spooled_bytes`.
BuildDiskNeeds EstimateBuildDisk(uint64_t triangles, uint64_t spooled_bytes, bool attributes,
                                 const BuildOptions& options);

// Bytes a triangle takes in the spool and in bucket files (its attributes when the model has any).
uint64_t SpooledBytesPerTriangle(bool attributes);

// Most triangles a block may hold and still be under `max_block_bytes` in the worst case.
uint32_t MaxTrianglesPerBlock(uint32_t max_block_bytes, bool attributes);

}  // namespace raystack::prep
