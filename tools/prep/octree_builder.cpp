#include "tools/prep/octree_builder.h"

#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <thread>

#include "common/base/check.h"
#include "common/base/log.h"
#include "common/base/progress.h"
#include "common/geometry/next_float.h"
#include "common/store/block_layout.h"
#include "common/store/octree.h"
#include "tools/prep/block_pipeline.h"
#include "tools/prep/clip.h"
#include "tools/prep/write_behind.h"

namespace raystack::prep {
namespace {

using store::OctreeNode;

// Past this depth, cells are a few float ulps of the root wide: splitting means nothing.
constexpr int kMaxDepth = 24;
// See Builder(): how far above the target the leaf/split rule aims.
constexpr double kAimOverTarget = 1.3;
// Levels in a row where some child kept every triangle of its parent before we give up.
constexpr int kMaxStall = 4;
// A split whose largest child keeps a fraction k of the parent's references, while the
// children together hold g times as many, separates nothing worth its copies when k * g
// reaches this: coincident or stacked triangles give 3 to 8 (every child they cross keeps
// them all, level after level: the references multiplied until kMaxStall, or forever for a
// stack whose children each lose a few), while no split of the shared models or the
// generated ones gave more than 1.23, even with 1 KB blocks.
constexpr double kNoSeparation = 2.0;
// How much a run of such splits in a row may multiply the references before the cell is made
// a leaf. Not 1: a sheet lying across a splitting plane doubles at that one level (k = 1,
// g = 2 when it is all in one quadrant) and separates below it.
constexpr double kMaxRunGrowth = 4.0;
// The references the whole build may make, per source triangle (ordinary models need ~1.1):
// past it, cells stop splitting, so triangles that defeat kNoSeparation cannot fill the disk.
constexpr uint64_t kMaxReferencesPerTriangle = 4;
// The references any split may make, per source triangle, separating or not. Slivers long
// against the blocks (a face with thousands of corners on one long edge and two on the other,
// whose every split is long and thin) do separate at each level, a little, and took a 2 MB
// OBJ to 4,606 references per triangle and a 3.2 GB store; the shared models need ~1.1.
constexpr uint64_t kMaxReferencesPerTriangleEver = 32;
// Bucket files are written in pieces of this size (one being filled per bucket), with at
// most this many pieces waiting for the writer thread.
constexpr size_t kBucketWriteBytes = 64 << 10;
constexpr size_t kBucketWritesQueued = 64;
// Memory one triangle costs while its bucket is subdivided (the triangle plus ~2.5 refs).
constexpr uint64_t kBucketBytesPerTriangle = sizeof(PackedTriangle) + 3 * 28;

// The triangles of one bucket (or of the whole model when it fits), shared by its jobs.
struct Bucket {
  std::vector<PackedTriangle> triangles;
  std::vector<TriangleAttributes> attributes;  // empty when the model has none
};

// References splits may still add, per source triangle beyond the first; warned of once, when
// a split would overdraw it (the cell is then a leaf).
class ReferenceBudget {
 public:
  ReferenceBudget(uint64_t per_triangle, const char* why) : per_triangle_(per_triangle), why_(why) {}
  void Start(uint64_t triangles) {
    spare_ = (per_triangle_ - 1) * triangles;
    spent_ = false;
  }
  uint64_t spare() const { return spare_; }
  // Takes the references a split adds (`total` for `parent`); false, taking nothing, when
  // they would overdraw the budget.
  bool Take(uint64_t parent, uint64_t total) {
    if (total <= parent) return true;
    if (total - parent > spare_) {
      if (!spent_)
        LOG_WARNING("prep", "references reached %llu per triangle%s: the cells left stop "
                    "splitting, so some leaves hold several blocks",
                    static_cast<unsigned long long>(per_triangle_), why_);
      spent_ = true;
      return false;
    }
    spare_ -= total - parent;
    return true;
  }

 private:
  uint64_t per_triangle_;
  const char* why_;
  uint64_t spare_ = 0;
  bool spent_ = false;
};

struct Ref {
  uint32_t tri;
  Bounds3f bounds;  // clipped to the current cell
};

// Whether splitting a cell of `parent` references into children holding `total`, the largest
// `largest`, separates its triangles enough to pay for the copies (see kNoSeparation).
bool SplitSeparates(uint64_t parent, uint64_t largest, uint64_t total) {
  const double p = static_cast<double>(parent);
  return static_cast<double>(largest) * static_cast<double>(total) < kNoSeparation * p * p;
}

// The growth of the references over the run of splits that separate nothing this split would
// extend (`run_growth` so far; 1 again after a split that separates), or 0 when it would pass
// kMaxRunGrowth: the cell is then a leaf.
double RunGrowthAfter(double run_growth, uint64_t parent, uint64_t largest, uint64_t total) {
  if (parent == 0 || SplitSeparates(parent, largest, total)) return 1.0;
  const double grown = run_growth * static_cast<double>(total) / static_cast<double>(parent);
  return grown > kMaxRunGrowth ? 0.0 : grown;
}

// The cube the octree starts from: the model's box grown to its largest side, plus a margin
// so no triangle sits on the outer faces. Its centre is moved off the box's by kCentreShift of
// its half side along each axis: a triangle touching a split plane goes to the cells on both
// sides, and a flat model (or a model's planar part at its box's centre: a floor plan, a
// mirrored part's seam) lies on the root's split planes when the cube is centred: every such
// triangle was stored twice (a flat grid: 2.15 references per triangle). The shift has no short
// binary expansion, so no deeper split plane comes back onto the box's centre either.
constexpr float kCentreShift = 1.0f / 93.0f;

Bounds3f RootCell(const Bounds3f& model) {
  if (model.Empty()) return {{0, 0, 0}, {1, 1, 1}};
  const Vec3f e = model.Extent();
  float half = 0.5f * std::max({e.x, e.y, e.z});
  Vec3f c = model.Center();
  for (int a = 0; a < 3; ++a) {
    // Far from the origin a small model's shift may be under an ulp: then at least one ulp.
    const float shifted = c[a] + half * kCentreShift;
    c[a] = shifted > c[a] ? shifted : NextUp(c[a]);
  }
  const float magnitude = std::max({std::fabs(c.x), std::fabs(c.y), std::fabs(c.z), half});
  half = half * (1.001f + kCentreShift) + magnitude * 1e-6f + 1e-30f;
  return {{c.x - half, c.y - half, c.z - half}, {c.x + half, c.y + half, c.z + half}};
}

// Typical raw bytes per triangle in a block: indices, id, shared vertices, and ~0.36 BVH nodes
// (32 bytes each) with the default in-block BVH (leaves of up to 8; measured on the dragon).
double RawBytesPerTriangle(float vertices_per_triangle, bool attributes) {
  return 6.0 + 4.0 + 32.0 * 0.36 + static_cast<double>(vertices_per_triangle) * (attributes ? 32.0 : 12.0);
}

// Triangles a bucket may hold to be built in memory: two buckets may be in memory at once (one
// loading, one still encoding).
uint64_t BucketCapacity(uint64_t memory_bytes, bool attributes) {
  return std::max<uint64_t>(memory_bytes / 2 / (kBucketBytesPerTriangle + (attributes ? 60 : 0)), 4096);
}

class Builder {
 public:
  Builder(const BuildOptions& options, store::StoreWriter* writer, bool attributes)
      : options_(options), attributes_(attributes),
        pipeline_(options.encode_threads > 0 ? options.encode_threads : options.threads, writer,
                  options.shuffle, options.max_block_bytes, options.bvh) {
    bytes_per_triangle_ = RawBytesPerTriangle(options.vertices_per_triangle, attributes);
    // Leaves come out ~25% below what the ratio rule aims at (measured on the shared
    // models), so it aims that much above the target to land the mean on it.
    aim_bytes_ = kAimOverTarget * options.target_block_bytes;
    // Leaves are cut into chunks expected to fit the cap; the pipeline splits any that do not.
    max_tris_ = static_cast<uint32_t>(std::max(
        1.0, (options.max_block_bytes - sizeof(store::BlockHeader)) / bytes_per_triangle_ * 0.9));
    bucket_capacity_ = BucketCapacity(options.memory_bytes, attributes);
  }

  Status Run(const TriangleSource& source, BuildResult* result) {
    result->root_cell = root_ = RootCell(source.bounds());
    for (int a = 0; a < 3; ++a)  // the readers refuse coordinates this large; copies may reach them
      if (!std::isfinite(root_.lower[a]) || !std::isfinite(root_.upper[a]))
        return Status::Error("the model's box is too large for float coordinates (the octree's "
                             "cube around it overflows); keep coordinates within +-1e18");
    nodes_.push_back({0, 0, store::kOctreeEmpty, 0});
    separating_nothing_.Start(source.triangles());
    every_split_.Start(source.triangles());
    if (source.triangles() <= bucket_capacity_) {
      RAYSTACK_RETURN_IF_ERROR(BuildInMemory(source, 0, root_, 0, 1.0));
    } else {
      RAYSTACK_RETURN_IF_ERROR(Partition(source, 0, root_, 0, 0, 1.0));
    }
    RAYSTACK_RETURN_IF_ERROR(pipeline_.Drain());
    // Blocks got their ids as they were written: point each leaf at its range.
    for (const auto& [leaf, range] : pipeline_.leaf_blocks()) {
      if (range.count > 0xffff)
        return Status::Error(StrFormat("%u blocks in one octree cell (its triangles cannot be "
                                       "separated); a store allows 65535",
                                       range.count));
      nodes_[leaf] = {range.first, static_cast<uint16_t>(range.count), store::kOctreeLeaf, 0};
    }
    const PipelineStats s = pipeline_.stats();
    result->octree = std::move(nodes_);
    result->references = s.references;
    result->blocks = s.blocks;
    result->raw_bytes = s.raw_bytes;
    result->stored_bytes = s.stored_bytes;
    result->cap_splits = s.cap_splits;
    result->largest_raw_bytes = s.largest_raw_bytes;
    result->max_depth = static_cast<uint32_t>(max_depth_);
    result->multi_block_leaves = multi_block_leaves_;
    result->partition_passes = partition_passes_;
    return OkStatus();
  }

 private:
  double EstimateBytes(size_t triangles) const {
    return sizeof(store::BlockHeader) + bytes_per_triangle_ * static_cast<double>(triangles);
  }

  uint32_t AddChildren() {
    const uint32_t first = static_cast<uint32_t>(nodes_.size());
    nodes_.resize(nodes_.size() + 8, {0, 0, store::kOctreeEmpty, 0});
    return first;
  }

  // Loads a whole source (small model or one bucket) and subdivides it.
  // `run_growth` as in Subdivide.
  Status BuildInMemory(const TriangleSource& source, uint32_t node, const Bounds3f& cell,
                       int depth, double run_growth) {
    // Jobs of the previous bucket may still be encoding from its triangles: the new bucket
    // gets its own arrays, and jobs share ownership of theirs (so loading this bucket overlaps
    // encoding the last one). The bucket budget allows for two in memory, so the one before
    // must be done with first; the queue of jobs is long enough to keep the encoders busy
    // while a bucket loads.
    pipeline_.WaitUntil([&] { return older_bucket_.expired(); });
    older_bucket_ = previous_bucket_;
    auto bucket = std::make_shared<Bucket>();
    previous_bucket_ = bucket;
    bucket->triangles.reserve(source.triangles());

    RAYSTACK_RETURN_IF_ERROR(source.ForEach([&](std::span<const PackedTriangle> tris,
                                                std::span<const TriangleAttributes> attrs) {
      bucket->triangles.insert(bucket->triangles.end(), tris.begin(), tris.end());
      bucket->attributes.insert(bucket->attributes.end(), attrs.begin(), attrs.end());
      return OkStatus();
    }));
    bucket_ = bucket;
    std::vector<Ref> refs;
    refs.reserve(bucket->triangles.size());
    for (uint32_t i = 0; i < bucket->triangles.size(); ++i) {
      const Bounds3f b = ClipTriangleToCell(bucket->triangles[i].p, cell);
      if (!b.Empty()) refs.push_back({i, b});
    }
    Subdivide(node, cell, std::move(refs), depth, 0, run_growth);
    bucket_.reset();
    return OkStatus();
  }

  // Splits `refs` among the 8 children of `cell`; returns the size of the largest child.
  size_t SplitRefs(const Bounds3f& cell, const std::vector<Ref>& refs,
                   std::vector<Ref> (&kids)[8]) const {
    const Vec3f mid = (cell.lower + cell.upper) * 0.5f;
    for (const Ref& r : refs) {
      int lo_mask = 0, hi_mask = 0;  // which halves the box touches, per axis
      for (int a = 0; a < 3; ++a) {
        if (r.bounds.lower[a] <= mid[a]) lo_mask |= 1 << a;
        if (r.bounds.upper[a] >= mid[a]) hi_mask |= 1 << a;
      }
      if ((lo_mask & hi_mask) == 0) {
        // Wholly inside one child (the common case), whose index is the halves it touches:
        // its box stays as is.
        kids[hi_mask].push_back(r);
        continue;
      }
      for (int i = 0; i < 8; ++i) {
        bool touches = true;
        for (int a = 0; a < 3 && touches; ++a) touches = (i >> a & 1) ? (hi_mask >> a & 1) : (lo_mask >> a & 1);
        if (!touches) continue;
        const Bounds3f b = ClipTriangleToCell(bucket_->triangles[r.tri].p, store::ChildCell(cell, i));
        if (!b.Empty()) kids[i].push_back({r.tri, b});
      }
    }
    size_t largest = 0;
    for (const auto& k : kids) largest = std::max(largest, k.size());
    return largest;
  }

  // `stall` counts the levels in a row where some child kept every reference of its parent;
  // `run_growth` is what the splits above that separated nothing multiplied them by.
  void Subdivide(uint32_t node, const Bounds3f& cell, std::vector<Ref> refs, int depth,
                 int stall, double run_growth) {
    max_depth_ = std::max(max_depth_, depth);
    if (refs.empty()) return;  // stays kOctreeEmpty
    const bool must_split = EstimateBytes(refs.size()) > options_.max_block_bytes;
    const bool can_split = depth < kMaxDepth && stall < kMaxStall;
    if (!can_split) return MakeLeaf(node, cell, std::move(refs));
    if (!must_split && EstimateBytes(refs.size()) <= aim_bytes_)
      return MakeLeaf(node, cell, std::move(refs));

    std::vector<Ref> kids[8];
    const size_t largest = SplitRefs(cell, refs, kids);
    size_t filled = 0, total = 0;
    for (const auto& k : kids) {
      filled += !k.empty();
      total += k.size();
    }
    // Triangles that no split separates (coincident, stacked) stay together in one leaf of
    // several blocks, rather than being copied into every child level after level.
    const double next_growth = RunGrowthAfter(run_growth, refs.size(), largest, total);
    if (next_growth == 0.0) return MakeLeaf(node, cell, std::move(refs));
    if (!must_split) {
      // Leaf or split, whichever lands closer to the target size (in ratio).
      const double mean_child = EstimateBytes(total / std::max<size_t>(filled, 1));
      const double leaf_error = std::fabs(std::log(EstimateBytes(refs.size()) / aim_bytes_));
      const double split_error = std::fabs(std::log(mean_child / aim_bytes_));
      if (leaf_error <= split_error) return MakeLeaf(node, cell, std::move(refs));
    }
    // Only splits that separate nothing draw on the budget: a model that truly needs many
    // references (large triangles against small blocks) must not spend it in the order its
    // cells come, leaving the last ones unsplit (106x the block visits of a render, found in
    // review). Partition passes, which run before they know, draw on it for every split.
    if (next_growth != 1.0 && !separating_nothing_.Take(refs.size(), total))
      return MakeLeaf(node, cell, std::move(refs));
    if (!every_split_.Take(refs.size(), total)) return MakeLeaf(node, cell, std::move(refs));
    const int next_stall = largest == refs.size() ? stall + 1 : 0;
    std::vector<Ref>().swap(refs);  // free before recursing
    const uint32_t first = AddChildren();
    nodes_[node] = {first, 0, store::kOctreeInner, 0};
    for (int i = 0; i < 8; ++i) {
      Subdivide(first + static_cast<uint32_t>(i), store::ChildCell(cell, i), std::move(kids[i]),
                depth + 1, next_stall, next_growth);
    }
  }

  void MakeLeaf(uint32_t node, const Bounds3f& cell, std::vector<Ref> refs) {
    const size_t chunks = (refs.size() + max_tris_ - 1) / max_tris_;
    if (chunks > 1) ++multi_block_leaves_;
    nodes_[node] = {0, 0, store::kOctreeLeaf, 0};  // its blocks are filled in by Run()
    for (size_t c = 0; c < chunks; ++c) {
      LeafJob job;
      job.triangles = bucket_->triangles;
      job.attributes = bucket_->attributes;
      job.keep_alive = bucket_;
      const size_t begin = c * refs.size() / chunks, end = (c + 1) * refs.size() / chunks;
      job.refs.reserve(end - begin);
      job.ref_bounds.reserve(end - begin);
      for (size_t i = begin; i < end; ++i) {
        job.refs.push_back(refs[i].tri);
        job.ref_bounds.push_back(refs[i].bounds);
      }
      job.cell = cell;
      job.octree_leaf = node;
      CountProgress(bucket_->triangles, &refs[begin], &refs[end], cell);
      pipeline_.Submit(std::move(job));
    }
  }

  // The blocks' progress counts each triangle once, in the one leaf whose cell, half-open
  // ([lower, upper), closed at the root's upper faces), holds its first corner: that leaf
  // stores it, as the triangle touches its cell there. Counting references instead passed
  // 100% with a third of the work left (a triangle is stored in every leaf it crosses).
  void CountProgress(const std::vector<PackedTriangle>& triangles, const Ref* begin,
                     const Ref* end, const Bounds3f& cell) const {
    if (!options_.progress) return;
    uint64_t home = 0;
    for (const Ref* r = begin; r != end; ++r) {
      const Vec3f p = triangles[r->tri].p[0];
      bool inside = true;
      for (int a = 0; a < 3; ++a)
        inside &= p[a] >= cell.lower[a] && (p[a] < cell.upper[a] || cell.upper[a] == root_.upper[a]);
      home += inside;
    }
    options_.progress->Update(home);
  }

  // Splits a source too large for memory into the cells `levels` levels down, on disk.
  // `stall` counts the levels in a row where one bucket kept every triangle of its source;
  // `run_growth` as in Subdivide.
  Status Partition(const TriangleSource& source, uint32_t node, const Bounds3f& cell, int depth,
                   int stall, double run_growth);
  // One partition pass into the cells `levels` levels down. Stops early, setting `*over`,
  // once the buckets hold more than `max_references` triangles (the outcome does not depend
  // on the threads: the count only grows, and its last addition sees the final total).
  Status FillBuckets(const TriangleSource& source, uint32_t node, const Bounds3f& cell, int depth,
                     int levels, uint64_t max_references, struct BucketFiles* files, bool* over);
  // A source too large for memory that splitting cannot separate (coincident triangles, or the
  // depth limit): one leaf of several blocks, streamed a block at a time.
  Status StreamLeaf(const TriangleSource& source, uint32_t node, const Bounds3f& cell, int depth);

  const BuildOptions& options_;
  bool attributes_;
  BlockPipeline pipeline_;
  uint32_t max_tris_;
  double bytes_per_triangle_;
  double aim_bytes_;
  uint64_t bucket_capacity_;
  Bounds3f root_;
  // What splits that separate nothing (and partition passes) may add, and what every split may.
  ReferenceBudget separating_nothing_{kMaxReferencesPerTriangle, ""};
  ReferenceBudget every_split_{kMaxReferencesPerTriangleEver,
                               " (triangles long and thin against the blocks; rays through "
                               "those leaves are slower)"};
  std::vector<OctreeNode> nodes_;
  std::shared_ptr<const Bucket> bucket_;  // the one being subdivided
  // The last two buckets loaded (alive while jobs hold them).
  std::weak_ptr<const Bucket> previous_bucket_, older_bucket_;
  int max_depth_ = 0;
  uint32_t multi_block_leaves_ = 0, partition_passes_ = 0;
};

// A bucket on disk, readable as a source: the files its pieces wrote (one per thread of the
// partition pass), read in order.
class BucketSource : public TriangleSource {
 public:
  BucketSource(std::vector<const TriangleSpool*> spools, Bounds3f bounds, bool attributes)
      : spools_(std::move(spools)), bounds_(bounds), attributes_(attributes) {}
  Status ForEach(const TriangleSpool::Visitor& visit) const override {
    for (const TriangleSpool* s : spools_) RAYSTACK_RETURN_IF_ERROR(s->ForEach(visit));
    return OkStatus();
  }
  int MaxParts() const override { return static_cast<int>(spools_.size()); }
  Status ForEachPart(int part, int parts, const TriangleSpool::Visitor& visit) const override {
    const size_t n = spools_.size();
    for (size_t i = n * static_cast<size_t>(part) / static_cast<size_t>(parts);
         i < n * static_cast<size_t>(part + 1) / static_cast<size_t>(parts); ++i)
      RAYSTACK_RETURN_IF_ERROR(spools_[i]->ForEach(visit));
    return OkStatus();
  }
  uint64_t triangles() const override {
    uint64_t n = 0;
    for (const TriangleSpool* s : spools_) n += s->triangles();
    return n;
  }
  uint64_t bytes() const override {
    uint64_t n = 0;
    for (const TriangleSpool* s : spools_) n += s->bytes();
    return n;
  }
  Bounds3f bounds() const override { return bounds_; }
  bool has_attributes() const override { return attributes_; }

 private:
  std::vector<const TriangleSpool*> spools_;
  Bounds3f bounds_;
  bool attributes_;
};

// The bucket files of a partition pass: one file per bucket and piece of the source.
struct BucketFiles {
  // Declared before the buckets, which flush through it until they are destroyed.
  std::unique_ptr<WriteBehind> writer;
  std::vector<std::vector<TriangleSpool>> pieces;

  uint64_t Triangles(uint32_t bucket) const {
    uint64_t n = 0;
    for (const auto& piece : pieces) n += piece[bucket].triangles();
    return n;
  }
  // Deletes the files (before a pass that reuses their names).
  void Reset() {
    pieces.clear();
    writer.reset();
  }
};

// Appends to `out` the index (in Morton order) of every level-`levels` cell below `cell` that
// triangle `t` overlaps; `bounds` is its box clipped to `cell`.
void Classify(const PackedTriangle& t, const Bounds3f& bounds, const Bounds3f& cell, int levels,
              uint32_t morton, std::vector<uint32_t>* out) {
  if (levels == 0) {
    out->push_back(morton);
    return;
  }
  const Vec3f mid = (cell.lower + cell.upper) * 0.5f;
  for (int i = 0; i < 8; ++i) {
    bool touches = true;
    for (int k = 0; k < 3 && touches; ++k)
      touches = (i >> k & 1) ? bounds.upper[k] >= mid[k] : bounds.lower[k] <= mid[k];
    if (!touches) continue;
    const Bounds3f child = store::ChildCell(cell, i);
    const Bounds3f b = child.Contains(bounds) ? bounds : ClipTriangleToCell(t.p, child);
    if (b.Empty()) continue;
    Classify(t, b, child, levels - 1, morton * 8 + static_cast<uint32_t>(i), out);
  }
}

// The level-`levels` cells below a cell, as their planes along each axis: planes[a][k] is
// the lower face of the k-th slab, computed by the same midpoint arithmetic as
// store::ChildCell, so a cell found here is the cell Classify would reach, bit for bit.
struct CellGrid {
  int levels = 0;
  std::vector<float> planes[3];  // (1 << levels) + 1 per axis

  CellGrid(const Bounds3f& cell, int depth) : levels(depth) {
    const size_t n = size_t{1} << levels;
    for (int a = 0; a < 3; ++a) {
      planes[a].assign(n + 1, 0.0f);
      planes[a][0] = cell.lower[a];
      planes[a][n] = cell.upper[a];
      Halve(planes[a], 0, n);
    }
  }

  // The Morton index of the one cell that holds `b` strictly inside (touching no face of a
  // cell, so Classify would neither clip it nor send it to a neighbour); false if none does.
  bool CellOf(const Bounds3f& b, uint32_t* morton) const {
    uint32_t slab[3];
    const size_t n = planes[0].size() - 1;
    for (int a = 0; a < 3; ++a) {
      const std::vector<float>& p = planes[a];
      size_t k = 0;
      while (k + 1 < n && p[k + 1] < b.lower[a]) ++k;
      if (!(p[k] < b.lower[a] && b.upper[a] < p[k + 1])) return false;
      slab[a] = static_cast<uint32_t>(k);
    }
    uint32_t m = 0;
    for (int bit = levels - 1; bit >= 0; --bit)
      m = m * 8 + ((slab[0] >> bit & 1) | (slab[1] >> bit & 1) << 1 | (slab[2] >> bit & 1) << 2);
    *morton = m;
    return true;
  }

 private:
  static void Halve(std::vector<float>& p, size_t lo, size_t hi) {
    if (hi - lo < 2) return;
    const size_t mid = (lo + hi) / 2;
    p[mid] = (p[lo] + p[hi]) * 0.5f;
    Halve(p, lo, mid);
    Halve(p, mid, hi);
  }
};

// How many pieces may each keep `buckets` files open: Debian's default soft limit (1024
// descriptors) is below two pieces of 512 buckets, so it is raised towards the hard limit
// first, and the pieces are fewer if that is not enough.
int PiecesWithinFileLimit(int pieces, uint32_t buckets) {
  constexpr uint64_t kSpareDescriptors = 64;  // the store, inputs, logs
  const uint64_t needed = uint64_t{buckets} * static_cast<uint64_t>(pieces) + kSpareDescriptors;
  rlimit limit{};
  if (getrlimit(RLIMIT_NOFILE, &limit) != 0) return 1;
  if (limit.rlim_cur != RLIM_INFINITY && limit.rlim_cur < needed) {
    rlimit raised = limit;
    raised.rlim_cur = limit.rlim_max == RLIM_INFINITY ? needed : std::min<rlim_t>(needed, limit.rlim_max);
    if (setrlimit(RLIMIT_NOFILE, &raised) == 0) limit = raised;
  }
  if (limit.rlim_cur == RLIM_INFINITY) return pieces;
  const uint64_t fit = limit.rlim_cur > kSpareDescriptors ? (limit.rlim_cur - kSpareDescriptors) / buckets : 0;
  return static_cast<int>(std::clamp<uint64_t>(fit, 1, static_cast<uint64_t>(pieces)));
}

// Appends each triangle of a batch to the bucket of every level-`levels` cell it overlaps;
// adds to `*appended` the triangles appended.
Status ClassifyBatch(std::span<const PackedTriangle> tris, std::span<const TriangleAttributes> attrs,
                     const Bounds3f& cell, const CellGrid& grid, std::vector<uint32_t>* cells,
                     std::vector<TriangleSpool>* buckets, uint64_t* appended) {
  for (size_t i = 0; i < tris.size(); ++i) {
    const Bounds3f b = ClipTriangleToCell(tris[i].p, cell);
    if (b.Empty()) continue;
    const TriangleAttributes* a = attrs.empty() ? nullptr : &attrs[i];
    uint32_t only;
    if (grid.CellOf(b, &only)) {  // most triangles: a lookup instead of a descent
      RAYSTACK_RETURN_IF_ERROR((*buckets)[only].Append(tris[i], a));
      ++*appended;
      continue;
    }
    cells->clear();
    Classify(tris[i], b, cell, grid.levels, 0, cells);
    for (uint32_t c : *cells) RAYSTACK_RETURN_IF_ERROR((*buckets)[c].Append(tris[i], a));
    *appended += cells->size();
  }
  return OkStatus();
}

Status Builder::StreamLeaf(const TriangleSource& source, uint32_t node, const Bounds3f& cell,
                           int depth) {
  max_depth_ = std::max(max_depth_, depth);
  uint32_t chunks = 0;
  auto bucket = std::make_shared<Bucket>();
  std::vector<Ref> refs;
  auto flush = [&]() {
    if (refs.empty()) return;
    LeafJob job;
    job.triangles = bucket->triangles;
    job.attributes = bucket->attributes;
    job.keep_alive = bucket;
    for (const Ref& r : refs) {
      job.refs.push_back(r.tri);
      job.ref_bounds.push_back(r.bounds);
    }
    job.cell = cell;
    job.octree_leaf = node;
    CountProgress(bucket->triangles, refs.data(), refs.data() + refs.size(), cell);
    pipeline_.Submit(std::move(job));
    ++chunks;
    refs.clear();
    bucket = std::make_shared<Bucket>();  // the job keeps the old one alive
  };
  RAYSTACK_RETURN_IF_ERROR(source.ForEach([&](std::span<const PackedTriangle> tris,
                                              std::span<const TriangleAttributes> attrs) {
    for (size_t i = 0; i < tris.size(); ++i) {
      const Bounds3f b = ClipTriangleToCell(tris[i].p, cell);
      if (b.Empty()) continue;
      refs.push_back({static_cast<uint32_t>(bucket->triangles.size()), b});
      bucket->triangles.push_back(tris[i]);
      if (!attrs.empty()) bucket->attributes.push_back(attrs[i]);
      if (refs.size() == max_tris_) flush();
    }
    return OkStatus();
  }));
  flush();
  if (chunks > 1) ++multi_block_leaves_;
  // Run() points the leaf at its blocks once they are written.
  nodes_[node] = {0, 0, chunks ? store::kOctreeLeaf : store::kOctreeEmpty, 0};
  return OkStatus();
}

Status Builder::FillBuckets(const TriangleSource& source, uint32_t node, const Bounds3f& cell,
                            int depth, int levels, uint64_t max_references, BucketFiles* files,
                            bool* over) {
  const uint32_t count = 1u << (3 * levels);
  const auto start = std::chrono::steady_clock::now();
  // The first pass is news; the passes over its buckets (dozens on a large model with a
  // small --mem-limit) are detail.
  RAYSTACK_LOG(depth == 0 ? LogLevel::kInfo : LogLevel::kDebug, "prep",
               "partitioning %llu triangles into %u buckets on disk (depth %d)",
               static_cast<unsigned long long>(source.triangles()), count, depth);
  // The source is read in pieces on `parts` threads, each with its own bucket files; a
  // bucket is then its pieces' files read in order, which is the source's order, so the
  // result does not depend on the number of threads. One writer thread copies the files'
  // buffers into the page cache (the kernel's work) behind them.
  const int parts = PiecesWithinFileLimit(std::clamp(options_.threads, 1, source.MaxParts()), count);
  files->writer = std::make_unique<WriteBehind>(kBucketWriteBytes / static_cast<size_t>(parts),
                                                kBucketWritesQueued);
  auto& pieces = files->pieces;
  pieces.resize(static_cast<size_t>(parts));
  for (int part = 0; part < parts; ++part) {
    pieces[part].reserve(count);
    for (uint32_t i = 0; i < count; ++i)
      pieces[part].emplace_back(StrFormat("%s/bucket-d%d-n%u-%u-%d.tmp", options_.temp_dir.c_str(),
                                          depth, node, i, part),
                                *files->writer);
  }
  const CellGrid grid(cell, levels);
  // The blocks' progress bar only moves once buckets are subdivided: this pass has its own.
  ProgressReporter progress(StrFormat("partitioning into %u buckets", count), source.triangles(),
                            "tri", options_.quiet || depth > 0);
  std::vector<Status> piece_status(static_cast<size_t>(parts));
  std::vector<char> stopped(static_cast<size_t>(parts), 0);  // by the reference limit
  std::atomic<uint64_t> references{0};
  std::atomic<bool> too_many{false};
  auto classify = [&](int part) {
    std::vector<uint32_t> cells;
    piece_status[part] = source.ForEachPart(
        part, parts,
        [&](std::span<const PackedTriangle> tris, std::span<const TriangleAttributes> attrs) {
          progress.Update(tris.size());
          uint64_t appended = 0;
          if (!too_many) {
            RAYSTACK_RETURN_IF_ERROR(
                ClassifyBatch(tris, attrs, cell, grid, &cells, &pieces[part], &appended));
            if (references.fetch_add(appended) + appended > max_references) too_many = true;
          }
          if (!too_many) return OkStatus();
          stopped[part] = 1;
          return Status::Error("too many references");  // ends this piece's scan
        });
    for (TriangleSpool& b : pieces[part])
      if (piece_status[part].ok()) piece_status[part] = b.Close();
  };
  std::vector<std::thread> helpers;
  for (int part = 1; part < parts; ++part) helpers.emplace_back(classify, part);
  classify(0);
  for (std::thread& h : helpers) h.join();
  for (int part = 0; part < parts; ++part)
    if (!stopped[part]) RAYSTACK_RETURN_IF_ERROR(piece_status[part]);
  *over = too_many;
  if (*over) {
    RAYSTACK_LOG(depth == 0 ? LogLevel::kInfo : LogLevel::kDebug, "prep",
                 "partition stopped: the buckets would hold more than %llu triangles",
                 static_cast<unsigned long long>(max_references));
    return OkStatus();
  }
  progress.Done();
  uint64_t bucket_bytes = 0;
  for (const auto& piece : pieces)
    for (const TriangleSpool& b : piece) bucket_bytes += b.bytes();
  // Like the start's line: only the first pass is news (a small --mem-limit gave 120 lines).
  RAYSTACK_LOG(depth == 0 ? LogLevel::kInfo : LogLevel::kDebug, "prep",
               "partitioned in %.1f s on %d thread%s (%.2f GB of bucket files)",
           std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), parts,
           parts == 1 ? "" : "s", static_cast<double>(bucket_bytes) / 1e9);
  return OkStatus();
}

Status Builder::Partition(const TriangleSource& source, uint32_t node, const Bounds3f& cell,
                          int depth, int stall, double run_growth) {
  ++partition_passes_;
  // Enough levels that an even spread fits in memory with room for unevenness; at most 3
  // (512 open bucket files).
  int levels = 1;
  while (levels < 3 && source.triangles() / (1ull << (3 * levels)) > bucket_capacity_ / 4) ++levels;
  if (depth + levels > kMaxDepth) levels = std::max(1, kMaxDepth - depth);
  // The buckets may hold the source and what is left of the reference budget. Past that, one
  // level may still do (a triangle reaches at most 8 of its cells, not 512); if even that is
  // over, the cell is a leaf.
  const uint64_t max_references = source.triangles() + separating_nothing_.spare();
  BucketFiles files;
  for (bool over = true; over;) {
    RAYSTACK_RETURN_IF_ERROR(
        FillBuckets(source, node, cell, depth, levels, max_references, &files, &over));
    if (!over) break;
    files.Reset();
    if (levels == 1) return StreamLeaf(source, node, cell, depth);
    levels = 1;
  }
  const uint32_t count = 1u << (3 * levels);
  uint64_t largest = 0, total = 0;
  for (uint32_t i = 0; i < count; ++i) {
    largest = std::max(largest, files.Triangles(i));
    total += files.Triangles(i);
  }
  // As in Subdivide: triangles the split does not separate stay in one leaf.
  const double next_growth = RunGrowthAfter(run_growth, source.triangles(), largest, total);
  if (next_growth == 0.0) {
    files.Reset();
    return StreamLeaf(source, node, cell, depth);
  }
  // The budget covers `total`: max_references left room for it.
  const bool taken = separating_nothing_.Take(source.triangles(), total);
  CHECK(taken);
  auto& pieces = files.pieces;

  // Walk the levels in Morton order, creating inner nodes; buckets become subtrees.
  struct Walk {
    Builder* self;
    std::vector<std::vector<TriangleSpool>>* pieces;
    int levels, base_depth, stall;
    double run_growth;
    uint64_t source_triangles;
    Status Go(uint32_t n, const Bounds3f& c, int level, uint32_t morton) {
      if (level == levels) {
        std::vector<const TriangleSpool*> files;
        uint64_t triangles = 0;
        for (const auto& piece : *pieces) {
          if (piece[morton].triangles() == 0) continue;
          files.push_back(&piece[morton]);
          triangles += piece[morton].triangles();
        }
        if (triangles == 0) return OkStatus();
        BucketSource sub(std::move(files), c, self->attributes_);
        const int depth = base_depth + level;
        // Without this, coincident triangles beyond the bucket capacity were partitioned
        // again and again, one level deeper each time, forever.
        const int next_stall = triangles >= source_triangles ? stall + levels : 0;
        Status s = triangles <= self->bucket_capacity_
                       ? self->BuildInMemory(sub, n, c, depth, run_growth)
                   : depth >= kMaxDepth || next_stall >= kMaxStall
                       ? self->StreamLeaf(sub, n, c, depth)
                       : self->Partition(sub, n, c, depth, next_stall, run_growth);
        for (auto& piece : *pieces) piece[morton].Clear();
        return s;
      }
      const uint32_t first = self->AddChildren();
      self->nodes_[n] = {first, 0, store::kOctreeInner, 0};
      bool any = false;
      for (int i = 0; i < 8; ++i) {
        RAYSTACK_RETURN_IF_ERROR(Go(first + static_cast<uint32_t>(i), store::ChildCell(c, i),
                                    level + 1, morton * 8 + static_cast<uint32_t>(i)));
        any |= self->nodes_[first + static_cast<uint32_t>(i)].kind != store::kOctreeEmpty;
      }
      if (!any) self->nodes_[n] = {0, 0, store::kOctreeEmpty, 0};
      return OkStatus();
    }
  } walk{this, &pieces, levels, depth, stall, next_growth, source.triangles()};
  return walk.Go(node, cell, 0, 0);
}

}  // namespace

uint32_t MaxTrianglesPerBlock(uint32_t max_block_bytes, bool attributes) {
  // Worst case: no shared vertex (3 per triangle) and one BVH leaf per triangle.
  auto worst = [&](uint32_t n) {
    store::BlockHeader h{};
    h.triangle_count = n;
    h.vertex_count = 3 * n;
    h.node_count = n ? 2 * n - 1 : 0;
    h.flags = store::kBlockPerTriangleMaterial | (3 * n > 65536 ? store::kBlockIndices32 : 0) |
              (attributes ? store::kBlockNormals | store::kBlockUvs : 0);
    return store::BlockLayout::For(h).total;
  };
  uint32_t lo = 1, hi = 1u << 20;
  while (lo < hi) {  // largest n with worst(n) <= cap
    const uint32_t m = lo + (hi - lo + 1) / 2;
    if (worst(m) <= max_block_bytes) lo = m;
    else hi = m - 1;
  }
  return lo;
}

uint64_t SpooledBytesPerTriangle(bool attributes) {
  return sizeof(PackedTriangle) + (attributes ? sizeof(TriangleAttributes) : 0);
}

BuildDiskNeeds EstimateBuildDisk(uint64_t triangles, uint64_t spooled_bytes, bool attributes,
                                 const BuildOptions& options) {
  BuildDiskNeeds needs;
  // The first partition pass writes every triangle once per bucket it reaches, as spooled;
  // later passes split one bucket at a time, their files a fraction of it. Measured: 6 M
  // triangles, --mem-limit 64: 0.27 GB of buckets after a 0.26 GB spool, 0.53 GB at the peak;
  // the dragon x27 (1.04 GB spooled), 1.04 GB at the peak, the store 1 MB then.
  if (triangles > BucketCapacity(options.memory_bytes, attributes))
    needs.temp_bytes = static_cast<uint64_t>(static_cast<double>(spooled_bytes) * 1.1);
  // Blocks: ~1.09 references a triangle at the raw size on meshes (the shared models), 1.45-2.44
  // on soups (a review: the estimate was a third under), lz4 with the shuffle ~1.6x (1.5-1.9).
  const double references = options.vertices_per_triangle > 1.5f ? 2.0 : 1.09;
  needs.store_bytes = static_cast<uint64_t>(static_cast<double>(triangles) * references *
                                            RawBytesPerTriangle(options.vertices_per_triangle, attributes) / 1.6);
  return needs;
}

BuildDiskNeeds EstimateBuildDisk(const TriangleSource& source, const BuildOptions& options) {
  return EstimateBuildDisk(source.triangles(), source.bytes(), source.has_attributes(), options);
}

Expected<BuildResult> BuildOctree(const TriangleSource& source, const BuildOptions& options,
                                  store::StoreWriter* writer) {
  Builder builder(options, writer, source.has_attributes());
  BuildResult result;
  RAYSTACK_RETURN_IF_ERROR(builder.Run(source, &result));
  return result;
}

}  // namespace raystack::prep
