#pragma once
/// \file
/// The SAH kd-tree for static geometry: Wald & Havran, "On building fast kd-Trees for Ray Tracing,
/// and on doing that in O(N log N)" (IEEE RT 2006).
///
/// Build: the event lists are sorted once per axis (a radix sort); every node then sweeps them for
/// the best SAH plane, classifies its triangles (below / above / both) and splits the lists in
/// linear time (a cut that leaves one side empty hands the node's lists to the other child
/// unchanged). Only the triangles that straddle the plane get new events: each is clipped to the
/// node's box and the clipped polygon split by the plane into its parts in the two child boxes
/// (Sutherland–Hodgman, the "perfect splits" of §4.2), and the short sorted lists of new events are
/// merged into the split lists. Subtrees above a size threshold are built in parallel (TBB) into
/// their own arrays and spliced, so the result is the same, node for node, for any thread count.
///
/// Layout: gpu::KdNode (shaders/shared/accel_layout.h), one contiguous array in depth-first order
/// (the child below the split is the next node), plus one array of triangle indices.
///
/// Traversal: front to back with a fixed stack (as in pbrt's KdTreeAggregate), its interval
/// decisions taken with a small relative slack; closest hit or any hit; a leaf of three or more
/// triangles tested four at a time (SSE lanes over triangles, the scalar loop's result to the
/// bit). Packets of 4 (SSE) or 8
/// (AVX2, chosen at run time) rays sharing their direction signs are traversed together (Wald et
/// al., "Interactive Rendering with Coherent Ray Tracing", 2001), other packets one lane at a time.

#include "specula/accel/common/ray_query.h"
#include "specula/shared/accel_layout.h"

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace specula::accel {

struct KdBuildOptions {
  float traversal_cost = 1.0f;    ///< K_T: cost of one interior node step
  /// K_I: cost of one triangle test, in units of K_T, measured rather than assumed: on the bench's
  /// scenes 1.0 traces every kind of ray as fast as 1.5 or faster, with a tree a third smaller
  /// built 1.2x faster; lower values build faster still but slow single rays (PERFORMANCE.md).
  float intersection_cost = 1.0f;
  float empty_bonus = 0.8f;       ///< λ: cost factor of a split with one empty side
  std::uint32_t max_depth = 0;    ///< 0: 8 + 1.3 log2 n; never more than 63 (the stack)
  std::uint32_t leaf_size = 1;    ///< nodes with this many triangles or fewer are never split
  bool perfect_splits = true;     ///< clip straddling triangles to the child boxes
  bool parallel = true;           ///< build large subtrees on the TBB pool
  /// AVX2 where the CPU has it: long event lists swept eight events at a time, and nodes of at
  /// most 16 triangles built from their triangles' boxes, every candidate plane of an axis
  /// weighed at once (the same costs, bit for bit, so the same tree; false: the event lists and
  /// the scalar sweep everywhere, for comparison).
  bool simd = true;
};

struct KdBuildStats {
  double build_ms = 0.0;
  std::uint32_t nodes = 0, leaves = 0, empty_leaves = 0, max_depth = 0;
  std::uint64_t leaf_references = 0;
  float sah_cost = 0.0f; ///< SAH cost of the tree (K_T per interior, K_I per reference, by area)
  std::size_t bytes = 0; ///< nodes and index array
  /// Work counters, for the complexity check (tests): events touched by the per-node linear
  /// passes (sweep, classification, list split, new events of straddling triangles), and the
  /// work of every sort: the root's radix sorts count the events they read and move (k per pass
  /// of k events), the comparison sorts of the straddlers' new events k·⌈log2 k⌉.
  std::uint64_t events_processed = 0;
  std::uint64_t sort_work = 0;
  std::uint32_t skipped_triangles = 0; ///< triangles left out for a non-finite vertex
};

class KdTree {
public:
  /// Builds over `tris`, which is kept by reference (its arrays must outlive the tree). Triangles
  /// with a non-finite vertex are left out; degenerate ones are kept.
  void build(const TriangleView& tris, const KdBuildOptions& options = {});

  [[nodiscard]] bool empty() const { return nodes_.empty(); }
  [[nodiscard]] const Aabb& bounds() const { return bounds_; }

  /// Closest hit within (r.tnear, r.tfar); on a hit r.tfar == hit.t and `hit` is overwritten.
  /// Returns whether it hit. `hit` is left alone on a miss, so one record can collect the closest
  /// hit over several structures.
  bool intersect(PreparedRay& r, TriangleHit& hit,
                 TriangleTest test = TriangleTest::watertight) const;
  /// Whether anything lies within (r.tnear, r.tfar).
  [[nodiscard]] bool occluded(const PreparedRay& r,
                              TriangleTest test = TriangleTest::watertight) const;

  /// Packets: lanes with active[i] == false are ignored. Like intersect(), a lane's hit and tfar
  /// are written only where a hit closer than rays.tfar[i] is found (clear() the hits first:
  /// prim[i] then stays 0xFFFFFFFF on a miss).
  void intersect4(RayPacket<4>& rays, PacketHits<4>& hits, const bool active[4],
                  TriangleTest test = TriangleTest::watertight) const;
  void intersect8(RayPacket<8>& rays, PacketHits<8>& hits, const bool active[8],
                  TriangleTest test = TriangleTest::watertight) const;

  /// Occlusion of a packet: the mask of active lanes whose ray meets a triangle within (tnear,
  /// tfar). Lanes that share their direction signs walk the tree together, each leaving it once
  /// a leaf blocks it; a lane's answer is its closest hit's existence, as the single ray's.
  /// occluded8 uses AVX2 where the CPU has it, else two packets of four.
  [[nodiscard]] unsigned occluded4(const RayPacket<4>& rays, const bool active[4],
                                   TriangleTest test = TriangleTest::watertight) const;
  [[nodiscard]] unsigned occluded8(const RayPacket<8>& rays, const bool active[8],
                                   TriangleTest test = TriangleTest::watertight) const;

  [[nodiscard]] std::span<const gpu::KdNode> nodes() const { return nodes_; }
  [[nodiscard]] std::span<const std::uint32_t> indices() const { return indices_; }
  [[nodiscard]] const KdBuildStats& stats() const { return stats_; }
  [[nodiscard]] const TriangleView& triangles() const { return tris_; }

private:
  template <TriangleTest Test, bool AnyHit>
  bool traverse(PreparedRay& r, TriangleHit* hit) const;
  /// A packet's walk: the lanes with a hit (AnyHit: blocked); their hits in lane_hits.
  template <int N, TriangleTest Test, bool AnyHit>
  unsigned walk_packet(const RayPacket<N>& rays, const bool* active, PreparedRay* prepared,
                       TriangleHit* lane_hits) const;
  template <int N, TriangleTest Test>
  unsigned occluded_packet(const RayPacket<N>& rays, const bool* active, TestTag<Test>) const;
  template <int N, TriangleTest Test>
  void intersect_packet(RayPacket<N>& rays, PacketHits<N>& hits, const bool* active,
                        TestTag<Test>) const;

  TriangleView tris_;
  Aabb bounds_;
  std::vector<gpu::KdNode> nodes_;
  std::vector<std::uint32_t> indices_;
  KdBuildStats stats_;
};

} // namespace specula::accel
