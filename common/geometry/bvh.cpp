// Binned-SAH BVH builder (Wald 2007, "On fast Construction of SAH-based Bounding Volume
// Hierarchies"). One call builds one block's tree of a few thousand primitives; the converter
// makes millions of calls, so the builder allocates only its outputs and keeps its scratch on
// the stack.

#include "common/geometry/bvh.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <cstdint>
#include <limits>
#include <thread>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "common/base/check.h"
#include "common/base/populate.h"

namespace raystack {
namespace {

constexpr uint32_t kNoParent = std::numeric_limits<uint32_t>::max();

// Four floats in one SSE register (x, y, z and an unused lane), or a plain array where SSE2 is
// missing. The builder's inner loops extend boxes and bin centroids for all three axes at
// once with these; every lane does the IEEE operation the scalar code did, on the same
// operands in the same order, so the tree is the same bit for bit.
#if defined(__SSE2__)
struct F4 {
  __m128 v;
  static F4 Load(const Vec3f& p) { return {_mm_set_ps(0.0f, p.z, p.y, p.x)}; }
  static F4 Splat(float f) { return {_mm_set1_ps(f)}; }
  friend F4 operator-(F4 a, F4 b) { return {_mm_sub_ps(a.v, b.v)}; }
  friend F4 operator*(F4 a, F4 b) { return {_mm_mul_ps(a.v, b.v)}; }
  friend F4 operator+(F4 a, F4 b) { return {_mm_add_ps(a.v, b.v)}; }
  // std::min(a, b) lane by lane: `b < a ? b : a`, which keeps `a` on ties (-0 against +0).
  friend F4 MinOf(F4 a, F4 b) { return {_mm_min_ps(b.v, a.v)}; }
  friend F4 MaxOf(F4 a, F4 b) { return {_mm_max_ps(b.v, a.v)}; }  // `b > a ? b : a`
  Vec3f ToVec3() const {
    alignas(16) float f[4];
    _mm_store_ps(f, v);
    return {f[0], f[1], f[2]};
  }
  float Lane(int a) const {
    alignas(16) float f[4];
    _mm_store_ps(f, v);
    return f[a];
  }
  // Bins of (x, y, z) as AxisBinning::BinOf computes them: `f < last ? int(f) : last`.
  void BinsOf(F4 last, int out[4]) const {
    const __m128i truncated = _mm_cvttps_epi32(v);
    const __m128i in_range = _mm_castps_si128(_mm_cmplt_ps(v, last.v));
    const __m128i clamped = _mm_cvttps_epi32(last.v);
    const __m128i bins = _mm_or_si128(_mm_and_si128(in_range, truncated),
                                      _mm_andnot_si128(in_range, clamped));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out), bins);
  }
};
#else
struct F4 {
  float v[4];
  static F4 Load(const Vec3f& p) { return {{p.x, p.y, p.z, 0.0f}}; }
  static F4 Splat(float f) { return {{f, f, f, f}}; }
  template <typename Op>
  static F4 Each(F4 a, F4 b, Op op) {
    return {{op(a.v[0], b.v[0]), op(a.v[1], b.v[1]), op(a.v[2], b.v[2]), op(a.v[3], b.v[3])}};
  }
  friend F4 operator-(F4 a, F4 b) { return Each(a, b, [](float x, float y) { return x - y; }); }
  friend F4 operator*(F4 a, F4 b) { return Each(a, b, [](float x, float y) { return x * y; }); }
  friend F4 operator+(F4 a, F4 b) { return Each(a, b, [](float x, float y) { return x + y; }); }
  friend F4 MinOf(F4 a, F4 b) { return Each(a, b, [](float x, float y) { return std::min(x, y); }); }
  friend F4 MaxOf(F4 a, F4 b) { return Each(a, b, [](float x, float y) { return std::max(x, y); }); }
  Vec3f ToVec3() const { return {v[0], v[1], v[2]}; }
  float Lane(int a) const { return v[a]; }
  void BinsOf(F4 last, int out[4]) const {
    for (int a = 0; a < 4; ++a) out[a] = v[a] < last.v[a] ? static_cast<int>(v[a]) : static_cast<int>(last.v[a]);
  }
};
#endif

// A box in two registers; starts empty (lower +inf, upper -inf) like Bounds3f.
struct Box4 {
  F4 lower = F4::Splat(std::numeric_limits<float>::infinity());
  F4 upper = F4::Splat(-std::numeric_limits<float>::infinity());

  static Box4 Load(const Bounds3f& b) { return {F4::Load(b.lower), F4::Load(b.upper)}; }
  void Extend(const Box4& b) {
    lower = MinOf(lower, b.lower);
    upper = MaxOf(upper, b.upper);
  }
  void Extend(F4 p) {
    lower = MinOf(lower, p);
    upper = MaxOf(upper, p);
  }
  Bounds3f ToBounds() const { return {lower.ToVec3(), upper.ToVec3()}; }
  float HalfArea() const { return ToBounds().HalfArea(); }
};

// A range of `order` that still needs a node. `patch` is the parent whose `offset` must point
// at this node: set for second children only, since a first child sits right after its parent.
// Carries its bounds so they are computed while partitioning the parent, not in a pass of
// their own.
struct BuildTask {
  uint32_t begin = 0;
  uint32_t end = 0;
  uint32_t patch = kNoParent;
  int depth = 0;
  Box4 bounds;
  Box4 centroid_bounds;
};

struct Bin {
  Box4 bounds;
};

// Half the sum keeps the centroid finite for boxes near the float range limit.
inline F4 Centroid(const Box4& b) {
  const F4 half = F4::Splat(0.5f);
  return b.lower * half + b.upper * half;
}

// Levels of median splits that bring `count` primitives down to leaves of `max_leaf`.
int MedianSplitLevels(uint32_t count, uint32_t max_leaf) {
  int levels = 0;
  for (uint64_t capacity = max_leaf; capacity < count; capacity *= 2) ++levels;
  return levels;
}

// Maps centroids to bins along one axis. Every caller uses this one function, so binning for
// the cost sweep and binning for the partition agree bit for bit.
struct AxisBinning {
  float lower = 0;
  float scale = 0;  // bins per unit length; 0 marks an axis that cannot be split
  int last_bin = 0;

  int BinOf(float c) const {
    const float f = (c - lower) * scale;
    // Written so that NaN (impossible for finite input, but cheap to rule out) lands in the
    // last bin instead of reaching an undefined float-to-int conversion.
    return f < static_cast<float>(last_bin) ? static_cast<int>(f) : last_bin;
  }
};

struct SplitChoice {
  int axis = -1;  // -1: no split separates the primitives
  int bin = 0;    // left side holds bins [0, bin]
  float cost = std::numeric_limits<float>::infinity();  // sum of area * count over both sides
};

// What every builder of one tree shares: the primitives' boxes and centroids (read only) and
// the order (each builder permutes only the ranges of its own tasks).
struct BuildInput {
  BuildInput(std::span<const BvhBuildPrimitive> prims, const BvhBuildOptions& build_options,
             std::vector<uint32_t>* build_order)
      : options(build_options), order(*build_order) {
    ReserveForWrite(&boxes, prims.size());
    ReserveForWrite(&centroids, prims.size());
    for (const BvhBuildPrimitive& p : prims) {
      boxes.push_back(Box4::Load(p.bounds));
      centroids.push_back(Centroid(boxes.back()));
    }
  }

  const BvhBuildOptions& options;
  std::vector<uint32_t>& order;
  std::vector<Box4> boxes;    // primitive bounds, by primitive index
  std::vector<F4> centroids;  // by primitive index, computed once
};

class BvhBuilder {
 public:
  BvhBuilder(BuildInput& input, std::vector<BvhNode>* nodes)
      : options_(input.options), order_(input.order), nodes_(*nodes), boxes_(input.boxes),
        centroids_(input.centroids) {}

  // The task covering every primitive.
  BuildTask Root() const {
    BuildTask root;
    root.end = static_cast<uint32_t>(boxes_.size());
    RangeBounds(&root);
    return root;
  }

  // Appends the subtree of `task` to the nodes, depth first (a node, its first child's
  // subtree, its second's), numbered from where the nodes end. A task for which `defer(task)`
  // returns true, the root's excepted, gets a node left empty for the caller to replace by its
  // subtree, built elsewhere.
  template <typename Defer>
  void Build(const BuildTask& top, Defer&& defer) {
    std::array<BuildTask, kBvhMaxDepth + 2> stack;  // pending tasks never exceed depth + 1
    int size = 0;
    stack[size++] = top;
    while (size > 0) {
      const BuildTask task = stack[--size];
      const auto index = static_cast<uint32_t>(nodes_.size());
      if (task.patch != kNoParent) nodes_[task.patch].offset = index;
      nodes_.push_back(BvhNode{});
      if (index != 0 && defer(task)) continue;
      BuildTask left, right;
      if (!BuildNode(task, index, &left, &right)) continue;  // leaf
      left.depth = right.depth = task.depth + 1;
      right.patch = index;
      // Second child first onto the stack so the first child is built next, at index + 1.
      stack[size++] = right;
      stack[size++] = left;
      DCHECK(size <= static_cast<int>(stack.size()));
    }
  }

 private:
  void RangeBounds(BuildTask* task) const {
    for (uint32_t i = task->begin; i < task->end; ++i) {
      task->bounds.Extend(boxes_[order_[i]]);
      task->centroid_bounds.Extend(centroids_[order_[i]]);
    }
  }

  // Fills nodes_[index] for the range of `task`. For an inner node, returns true and sets the
  // children's ranges and bounds; both are non-empty.
  bool BuildNode(const BuildTask& task, uint32_t index, BuildTask* left, BuildTask* right) {
    const Bounds3f bounds = task.bounds.ToBounds();
    const Bounds3f centroid_bounds = task.centroid_bounds.ToBounds();
    BvhNode& node = nodes_[index];
    for (int a = 0; a < 3; ++a) {
      node.lower[a] = bounds.lower[a];
      node.upper[a] = bounds.upper[a];
    }

    const uint32_t count = task.end - task.begin;
    const auto max_leaf = static_cast<uint32_t>(options_.max_leaf_size);
    const bool may_be_leaf = count <= max_leaf;
    // Invariant: depth + MedianSplitLevels(count) <= kBvhMaxDepth. Once SAH could break it,
    // only median splits are left, and each of them takes one level off the remaining need.
    const bool depth_forces_median =
        task.depth + MedianSplitLevels(count, max_leaf) >= kBvhMaxDepth;

    if (count == 1 || (may_be_leaf && depth_forces_median)) return MakeLeaf(node, task);
    if (centroid_bounds.lower == centroid_bounds.upper) {
      // Identical centroids: no plane separates them, so any split is as good as any other.
      if (may_be_leaf) return MakeLeaf(node, task);
      return MakeInner(node, bounds.MaxAxis(), task, task.begin + count / 2, left, right);
    }
    if (!depth_forces_median) {
      const SplitChoice split = FindSahSplit(task, centroid_bounds);
      if (split.axis >= 0) {
        // Costs scaled by the node's half area, so a node of zero area needs no division.
        const float area = bounds.HalfArea();
        const float leaf_cost = options_.intersection_cost * static_cast<float>(count) * area;
        const float split_cost =
            options_.traversal_cost * area + options_.intersection_cost * split.cost;
        if (may_be_leaf && leaf_cost <= split_cost) return MakeLeaf(node, task);
        PartitionAtBin(task, centroid_bounds, split, left, right);
        node.axis = static_cast<uint8_t>(split.axis);
        return true;
      }
      if (may_be_leaf) return MakeLeaf(node, task);
    }
    return MakeInner(node, centroid_bounds.MaxAxis(), task, MedianSplit(task, centroid_bounds),
                     left, right);
  }

  static bool MakeLeaf(BvhNode& node, const BuildTask& task) {
    node.offset = task.begin;
    node.count = static_cast<uint16_t>(task.end - task.begin);
    return false;
  }

  // An inner node split at `mid` by position (no binning to reuse): children's bounds by a pass.
  bool MakeInner(BvhNode& node, int axis, const BuildTask& task, uint32_t mid, BuildTask* left,
                 BuildTask* right) const {
    node.axis = static_cast<uint8_t>(axis);  // offset is patched when the second child is built
    left->begin = task.begin;
    left->end = right->begin = mid;
    right->end = task.end;
    RangeBounds(left);
    RangeBounds(right);
    return true;
  }

  // Small nodes get fewer bins: a bin per primitive already separates them about as well, and
  // the fixed cost of sweeping 16 bins per axis would dominate the thousands of tiny nodes.
  int BinCount(uint32_t count) const {
    return static_cast<int>(std::min<uint32_t>(static_cast<uint32_t>(options_.bins),
                                               std::max<uint32_t>(count, 2)));
  }

  AxisBinning Binning(const Bounds3f& centroid_bounds, int axis, int bins) const {
    AxisBinning binning;
    binning.lower = centroid_bounds.lower[axis];
    binning.last_bin = bins - 1;
    const float extent = centroid_bounds.upper[axis] - binning.lower;
    const float scale = static_cast<float>(bins) / extent;
    // A zero, subnormal or overflowing extent gives no usable scale: leave the axis unsplit.
    if (extent > 0 && std::isfinite(extent) && std::isfinite(scale)) binning.scale = scale;
    return binning;
  }

  // Bins every primitive of the task on the three axes at once (AxisBinning::BinOf per lane).
  void FillBins(const BuildTask& task, const std::array<AxisBinning, 3>& binning, int bins) {
    for (int a = 0; a < 3; ++a) {
      std::fill_n(bins_[a].begin(), bins, Bin{});
      std::fill_n(bin_counts_[a].begin(), bins, 0u);
    }
    const F4 lower = F4::Load({binning[0].lower, binning[1].lower, binning[2].lower});
    const F4 scale = F4::Load({binning[0].scale, binning[1].scale, binning[2].scale});
    const F4 last = F4::Splat(static_cast<float>(bins - 1));
    int bin[4];
    for (uint32_t i = task.begin; i < task.end; ++i) {
      const uint32_t p = order_[i];
      ((centroids_[p] - lower) * scale).BinsOf(last, bin);
      for (int a = 0; a < 3; ++a) {
        bins_[a][bin[a]].bounds.Extend(boxes_[p]);
        ++bin_counts_[a][bin[a]];
      }
    }
  }

  SplitChoice FindSahSplit(const BuildTask& task, const Bounds3f& centroid_bounds) {
    const int bins = BinCount(task.end - task.begin);
    std::array<AxisBinning, 3> binning;
    for (int a = 0; a < 3; ++a) binning[a] = Binning(centroid_bounds, a, bins);
    FillBins(task, binning, bins);

    SplitChoice best;
    std::array<float, kBvhMaxBins> right_cost;
    for (int a = 0; a < 3; ++a) {
      if (binning[a].scale == 0) continue;
      // right_cost[k]: area * count of bins (k, bins); 0 when they are all empty.
      Box4 right;
      uint32_t right_count = 0;
      for (int k = bins - 1; k > 0; --k) {
        right.Extend(bins_[a][k].bounds);
        right_count += bin_counts_[a][k];
        right_cost[k - 1] = right_count == 0 ? 0.0f
                                             : right.HalfArea() * static_cast<float>(right_count);
      }
      Box4 left;
      uint32_t left_count = 0;
      const uint32_t total = task.end - task.begin;
      for (int k = 0; k < bins - 1; ++k) {
        left.Extend(bins_[a][k].bounds);
        left_count += bin_counts_[a][k];
        if (left_count == 0 || left_count == total) continue;
        const float cost = left.HalfArea() * static_cast<float>(left_count) + right_cost[k];
        if (cost < best.cost) best = {a, k, cost};  // strict: ties keep the first, for determinism
      }
    }
    return best;
  }

  // Hoare partition that gathers each side's bounds on the way, so children need no pass.
  void PartitionAtBin(const BuildTask& task, const Bounds3f& centroid_bounds,
                      const SplitChoice& split, BuildTask* left, BuildTask* right) {
    const AxisBinning binning =
        Binning(centroid_bounds, split.axis, BinCount(task.end - task.begin));
    auto goes_left = [&](uint32_t p) {
      return binning.BinOf(centroids_[p].Lane(split.axis)) <= split.bin;
    };
    auto add = [&](BuildTask* side, uint32_t p) {
      side->bounds.Extend(boxes_[p]);
      side->centroid_bounds.Extend(centroids_[p]);
    };
    uint32_t i = task.begin, j = task.end;
    while (true) {
      while (i < j && goes_left(order_[i])) add(left, order_[i++]);
      while (i < j && !goes_left(order_[j - 1])) add(right, order_[--j]);
      if (i == j) break;
      std::swap(order_[i], order_[j - 1]);
    }
    CHECK(i > task.begin && i < task.end);
    left->begin = task.begin;
    left->end = right->begin = i;
    right->end = task.end;
  }

  // Object median along the widest centroid axis; ties broken by primitive index so the
  // result does not depend on the order the range happens to be in.
  uint32_t MedianSplit(const BuildTask& task, const Bounds3f& centroid_bounds) {
    const int axis = centroid_bounds.MaxAxis();
    const uint32_t mid = task.begin + (task.end - task.begin) / 2;
    std::nth_element(order_.begin() + task.begin, order_.begin() + mid, order_.begin() + task.end,
                     [&](uint32_t p, uint32_t q) {
                       const float cp = centroids_[p].Lane(axis);
                       const float cq = centroids_[q].Lane(axis);
                       return cp < cq || (cp == cq && p < q);
                     });
    return mid;
  }

  const BvhBuildOptions& options_;
  std::vector<uint32_t>& order_;
  std::vector<BvhNode>& nodes_;
  const std::vector<Box4>& boxes_;
  const std::vector<F4>& centroids_;
  // Reused by every node; only the first options_.bins entries per axis are ever touched.
  std::array<std::array<Bin, kBvhMaxBins>, 3> bins_;
  std::array<std::array<uint32_t, kBvhMaxBins>, 3> bin_counts_;
};

// Room for a tree over n > 0 primitives, reserved before it is built: at most 2n - 1 nodes, so
// they are never copied as the tree grows. No leaf holds more than max_leaf_size primitives, so
// there are at least 2 * ceil(n / max_leaf_size) - 1: those are mapped in one call
// (ReserveForWrite), the rest one page at a time as the tree reaches them.
void ReserveNodes(std::vector<BvhNode>* nodes, size_t n, const BvhBuildOptions& options) {
  nodes->reserve(2 * n - 1);
  const auto max_leaf = static_cast<size_t>(options.max_leaf_size);
  ReserveForWrite(nodes, 2 * ((n + max_leaf - 1) / max_leaf) - 1);
}

// Below this many primitives a tree is built on one thread: the converter's block trees, and
// anything that builds in a few milliseconds.
constexpr size_t kParallelBuildMin = 1 << 16;

// The same tree as one builder makes, bit for bit, on `threads` threads. The top of the tree is
// built first, down to subtrees of at most 1/(4 x threads) of the primitives; the threads then
// build those subtrees, the largest first, each into nodes of its own (their ranges of the
// order are disjoint); and the subtrees are moved into the empty nodes the top left for them,
// which is where one builder, going depth first, would have put them.
void BuildInParallel(BuildInput& input, const BuildTask& root, uint32_t threads,
                     std::vector<BvhNode>* nodes) {
  const uint32_t cutoff = std::max<uint32_t>(root.end / (4 * threads), 1024);
  struct Deferred {
    uint32_t slot;  // the top's empty node
    BuildTask task;
    std::vector<BvhNode> nodes;
  };
  std::vector<Deferred> deferred;
  std::vector<BvhNode> top;
  BvhBuilder(input, &top).Build(root, [&](const BuildTask& task) {
    if (task.end - task.begin > cutoff) return false;
    deferred.push_back({static_cast<uint32_t>(top.size() - 1), task, {}});
    return true;
  });

  std::vector<uint32_t> largest_first(deferred.size());
  for (uint32_t k = 0; k < largest_first.size(); ++k) largest_first[k] = k;
  std::sort(largest_first.begin(), largest_first.end(), [&](uint32_t a, uint32_t b) {
    return deferred[a].task.end - deferred[a].task.begin > deferred[b].task.end - deferred[b].task.begin;
  });
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t k; (k = next.fetch_add(1)) < largest_first.size();) {
      Deferred& d = deferred[largest_first[k]];
      BuildTask task = d.task;
      task.patch = kNoParent;
      ReserveNodes(&d.nodes, task.end - task.begin, input.options);
      BvhBuilder(input, &d.nodes).Build(task, [](const BuildTask&) { return false; });
    }
  };
  std::vector<std::thread> pool;
  for (uint32_t t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
  for (std::thread& t : pool) t.join();

  // Where each top node lands: after the subtrees that replace the empty nodes before it.
  std::vector<uint32_t> moved(top.size());
  uint32_t shift = 0;
  size_t d = 0;
  for (uint32_t i = 0; i < top.size(); ++i) {
    moved[i] = i + shift;
    if (d < deferred.size() && deferred[d].slot == i)
      shift += static_cast<uint32_t>(deferred[d++].nodes.size()) - 1;
  }
  ReserveForWrite(nodes, top.size() + shift);  // the whole tree, now that its size is known
  d = 0;
  for (uint32_t i = 0; i < top.size(); ++i) {
    if (d < deferred.size() && deferred[d].slot == i) {
      const auto base = static_cast<uint32_t>(nodes->size());
      for (BvhNode n : deferred[d++].nodes) {
        if (n.count == 0) n.offset += base;  // inner: its second child; a leaf's is the order's
        nodes->push_back(n);
      }
    } else {
      BvhNode n = top[i];
      if (n.count == 0) n.offset = moved[n.offset];
      nodes->push_back(n);
    }
  }
}

}  // namespace

std::vector<BvhNode> BuildBvh(std::span<const BvhBuildPrimitive> prims,
                              const BvhBuildOptions& options, std::vector<uint32_t>* order) {
  CHECK(order != nullptr);
  CHECK(options.max_leaf_size >= 1 && options.max_leaf_size <= 65535);
  CHECK(options.bins >= 2 && options.bins <= kBvhMaxBins);
  CHECK(prims.size() < std::numeric_limits<uint32_t>::max());
  ReserveForWrite(order, prims.size());
  order->resize(prims.size());
  for (uint32_t i = 0; i < order->size(); ++i) {
    const Bounds3f& b = prims[i].bounds;
    CHECK(!b.Empty() && IsFinite(b.lower) && IsFinite(b.upper));
    (*order)[i] = i;
  }
  std::vector<BvhNode> nodes;
  if (prims.empty()) return nodes;
  ReserveNodes(&nodes, prims.size(), options);
  BuildInput input(prims, options, order);
  BvhBuilder builder(input, &nodes);
  const BuildTask root = builder.Root();
  const auto threads = static_cast<uint32_t>(std::max(options.threads, 1));
  if (threads == 1 || prims.size() < kParallelBuildMin) {
    builder.Build(root, [](const BuildTask&) { return false; });
    return nodes;
  }
  BuildInParallel(input, root, threads, &nodes);
  return nodes;
}

}  // namespace raystack
