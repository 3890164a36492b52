#pragma once
/// \file
/// The BVH for dynamic objects (Bui Phu & Le, "Yet Another Real-Time Ray Tracer": a BVH that is
/// refitted every frame, selectively restructured where it degraded, and built lazily).
///
///   - Build: binned SAH (Wald, "On fast Construction of SAH-based Bounding Volume Hierarchies",
///     IRT 2007): centroids binned on all three axes, the cheapest plane of the sweep wins; leaves
///     of at most max_leaf primitives. The top levels are built as parallel tasks whose node
///     arrays are stitched in the order the sequential build writes them, so the result does not
///     depend on the thread count. Below depth kSahDepthLimit the build falls back to median
///     splits, which bounds the depth (and the traversal stack) for any input.
///   - Refit: same topology, boxes recomputed bottom-up from the vertices (children always sit
///     after their parent in the array, so one reverse sweep does it).
///   - Selective restructuring (Yoon, Curtis & Manocha, "Ray tracing dynamic scenes using
///     selective restructuring", 2007): each subtree's SAH cost, relative to its own root's area,
///     is recorded when it is built; the highest subtrees whose cost grew past a threshold are
///     rebuilt in place.
///   - Lazy construction: only the top lazy_depth levels are built; a deeper subtree stays an
///     unbuilt node (count = kBvhUnbuilt | primitive count, index = its first entry) until a
///     traversal first reaches it. Expansion is thread-safe: one mutex per tree, nodes read with
///     an acquire load of `count`, and the node array sized for the worst case (2n - 1) up front
///     so it never moves under readers.
///
/// Layout: gpu::BvhNode (specula/shared/accel_layout.h), one array of nodes and one of primitive
/// indices, uploaded as is by the Vulkan path (after expand_all()). A node's two children are
/// adjacent. Slots that a restructure freed are unreachable holes, marked as unbuilt nodes over
/// no entries.

#include "specula/accel/common/ray_query.h"
#include "specula/shared/accel_layout.h"

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <span>
#include <vector>

namespace specula::accel {

struct BvhBuildOptions {
  std::uint32_t bins = 16;     ///< SAH bins per axis, clamped to [2, 64]
  std::uint32_t max_leaf = 4;  ///< at most this many primitives per leaf (at least 1)
  float traversal_cost = 1.0f; ///< SAH cost of visiting an interior node
  float intersection_cost = 1.0f;
  bool lazy = false;           ///< subtrees below the top lazy_depth levels are built on first visit
  std::uint32_t lazy_depth = 6; ///< at least 1
};

struct BvhStats {
  double build_ms = 0.0;
  std::uint32_t nodes = 0, leaves = 0, max_depth = 0; ///< reachable nodes (unbuilt ones count once)
  float sah_cost = 0.0f;  ///< SAH cost of the tree after the last build or restructure
  std::size_t bytes = 0;  ///< node and index arrays, as allocated
  std::uint32_t lazy_expansions = 0;
};

struct RestructureStats {
  std::uint32_t subtrees_rebuilt = 0;
  std::uint32_t primitives_rebuilt = 0; ///< under the rebuilt subtrees
  std::uint32_t nodes_visited = 0;
  float sah_before = 0.0f, sah_after = 0.0f;
  double ms = 0.0;
};

class Bvh {
public:
  Bvh();
  Bvh(Bvh&&) noexcept;
  Bvh& operator=(Bvh&&) noexcept;
  ~Bvh();

  /// Builds over triangles (primitive = triangle index in `tris`). The view is kept (not its
  /// data) for intersect() and lazy expansion: it must stay valid until the next build or refit.
  /// Triangles with non-finite vertices get empty boxes: they are placed, never hit.
  void build(const TriangleView& tris, const BvhBuildOptions& options = {});
  /// Builds over boxes (primitive = box index): the top level over instances. Empty or NaN boxes
  /// are placed but never entered.
  void build(std::span<const Aabb> boxes, const BvhBuildOptions& options = {});

  /// Same topology, new vertex positions (same triangle count and indices): every box is
  /// recomputed bottom-up.
  void refit(const TriangleView& tris);
  void refit(std::span<const Aabb> boxes);

  /// Rebuilds (binned SAH, in place) the highest subtrees whose SAH cost, relative to their cost
  /// when last built, grew past `threshold` (e.g. 1.3); the whole tree only if the root degraded.
  /// Expects the boxes to be current: call refit(tris) first.
  RestructureStats restructure(const TriangleView& tris, float threshold);
  RestructureStats restructure(std::span<const Aabb> boxes, float threshold);

  [[nodiscard]] bool empty() const { return used_ == 0; }
  [[nodiscard]] Aabb bounds() const;

  /// Closest hit among the triangles (a tree built over triangles): on a hit closer than r.tfar,
  /// updates `hit`, sets r.tfar = hit.t and returns true. An invalid ray misses.
  bool intersect(PreparedRay& r, TriangleHit& hit, TriangleTest test = TriangleTest::watertight) const;
  /// Whether any triangle lies within (r.tnear, r.tfar).
  [[nodiscard]] bool occluded(const PreparedRay& r, TriangleTest test = TriangleTest::watertight) const;
  /// Packets: the closest hit per active lane (hits and rays.tfar updated where closer). Inactive
  /// lanes and invalid rays are left untouched. intersect8 uses AVX2 where the CPU has it, else
  /// two 4-packets.
  void intersect4(RayPacket<4>& rays, PacketHits<4>& hits, const bool active[4],
                  TriangleTest test = TriangleTest::watertight) const;
  void intersect8(RayPacket<8>& rays, PacketHits<8>& hits, const bool active[8],
                  TriangleTest test = TriangleTest::watertight) const;

  /// Generic traversal (the top level over instances): calls leaf(prim, r) for each primitive of
  /// each leaf whose box the ray enters, nearer child first. `leaf` may shrink r.tfar (closest
  /// hit: farther subtrees are then skipped) and returns true to stop (any hit).
  template <typename Leaf>
  void traverse(PreparedRay& r, Leaf&& leaf) const;

  /// The arrays as laid out (holes included; unbuilt nodes unless expand_all() ran).
  [[nodiscard]] std::span<const gpu::BvhNode> nodes() const { return {nodes_.data(), used_}; }
  [[nodiscard]] std::span<const std::uint32_t> indices() const { return indices_; }
  [[nodiscard]] const BvhStats& stats() const { return stats_; }
  /// The SAH cost of the tree as it is now (normalised by the root's area; one pass).
  [[nodiscard]] float sah_cost() const;
  /// Expands every unbuilt node (before handing the arrays to a GPU, or for tests).
  void expand_all() const;

  /// Depth below which the build uses median splits (so depth stays below kSahDepthLimit + 33).
  static constexpr std::uint32_t kSahDepthLimit = 48;
  static constexpr int kStackSize = 128;

private:
  template <TriangleTest Test>
  bool intersect_impl(PreparedRay& r, TriangleHit& hit) const;
  template <TriangleTest Test>
  bool occluded_impl(const PreparedRay& r) const;
  template <int N, TriangleTest Test>
  void intersect_packet(RayPacket<N>& rays, PacketHits<N>& hits, const bool* active,
                        TestTag<Test>) const;

  [[nodiscard]] std::uint32_t load_count(std::uint32_t node) const {
    return std::atomic_ref<std::uint32_t>(nodes_[node].count).load(std::memory_order_acquire);
  }
  /// Builds unbuilt node `node` (thread-safe); returns its new count (0: interior).
  std::uint32_t expand(std::uint32_t node) const;

  void build_common(std::span<const Aabb> prim_boxes, const BvhBuildOptions& options);
  void refit_nodes(const TriangleView* tris, std::span<const Aabb> boxes);
  RestructureStats restructure_common(const TriangleView* tris, std::span<const Aabb> boxes,
                                      float threshold);
  /// Returns the number of primitives under `root`.
  std::uint32_t rebuild_subtree(std::uint32_t root, std::uint32_t depth, const TriangleView* tris,
                                std::span<const Aabb> boxes);
  void compact();
  void update_stats();
  void subtree_costs(std::vector<float>& s) const;

  // Lazy expansion appends nodes and writes their costs from const traversals (under mutex_).
  mutable std::vector<gpu::BvhNode> nodes_;
  mutable std::vector<std::uint32_t> indices_;
  mutable std::vector<float> built_cost_;        ///< per node: SAH cost / root area when built
  mutable std::vector<std::uint8_t> lazy_depth_; ///< per node (lazy trees): depth of an unbuilt node
  mutable std::size_t used_ = 0;                 ///< slots in use in nodes_
  mutable BvhStats stats_;
  std::uint32_t holes_ = 0;
  std::uint32_t prim_count_ = 0;
  BvhBuildOptions options_;
  TriangleView tris_;            ///< the triangles (a tree over triangles)
  bool over_triangles_ = false;
  std::vector<Aabb> lazy_boxes_; ///< a lazy tree over boxes: the boxes, for expansion
  std::unique_ptr<std::mutex> mutex_;
};

template <typename Leaf>
void Bvh::traverse(PreparedRay& r, Leaf&& leaf) const {
  if (nodes_.empty() || !r.valid()) return;
  float t_enter, t_exit;
  if (!intersect_box(r, nodes_[0].bounds_min, nodes_[0].bounds_max, t_enter, t_exit)) return;
  struct Entry {
    std::uint32_t node;
    float t_enter;
  };
  Entry stack[kStackSize];
  int top = 0;
  std::uint32_t node = 0;
  for (;;) {
    std::uint32_t count = load_count(node);
    if (count & gpu::kBvhUnbuilt) count = expand(node);
    const std::uint32_t index = nodes_[node].index;
    if (count == 0) {
      const gpu::BvhNode& c0 = nodes_[index];
      const gpu::BvhNode& c1 = nodes_[index + 1];
      float e0, x0, e1, x1;
      const bool hit0 = intersect_box(r, c0.bounds_min, c0.bounds_max, e0, x0);
      const bool hit1 = intersect_box(r, c1.bounds_min, c1.bounds_max, e1, x1);
      if (hit0 && hit1) {
        if (e1 < e0) {
          stack[top++] = {index, e0};
          node = index + 1;
        } else {
          stack[top++] = {index + 1, e1};
          node = index;
        }
        continue;
      }
      if (hit0 || hit1) {
        node = hit0 ? index : index + 1;
        continue;
      }
    } else {
      for (std::uint32_t i = index; i < index + count; ++i)
        if (leaf(indices_[i], r)) return;
    }
    // Pop the nearest pending subtree the ray can still reach (r.tfar may have shrunk).
    for (;;) {
      if (top == 0) return;
      const Entry e = stack[--top];
      if (e.t_enter <= r.tfar) {
        node = e.node;
        break;
      }
    }
  }
}

} // namespace specula::accel
