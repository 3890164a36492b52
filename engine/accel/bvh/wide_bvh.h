#pragma once
/// \file
/// A 4-wide BVH, collapsed from a built binary Bvh (bvh.h): each node holds the
/// boxes of up to four children side by side (one SSE register per axis and side), so one ray
/// tests four boxes in a handful of vector instructions and walks about half as many levels.
/// This is how Embree's single-ray kernels work (BVH4/BVH8); Specula's binary BVH tests one box
/// at a time and pays a step per level.
///
///   - Collapse (Wald, Benthin & Boulos, "Getting Rid of Packets", RT 2008): from the binary root,
///     the interior child with the largest surface area is opened (replaced by its two children)
///     until four children are held or only leaves are left; leaves and their primitive ranges
///     are the binary tree's own, and the index array is copied as it is.
///   - Leaves: each binary leaf's triangles copied in groups of four (WideTriangles: vertices by
///     component, one lane a triangle), tested against the ray four at a time with Woop et al.'s
///     watertight test written lane-wise: the same operations in the same order as the scalar test
///     (intersect_watertight), its double-precision fallback taken lane by lane. Möller–Trumbore
///     (the option) reads the same copies one triangle at a time.
///   - Traversal: the slab test of intersect_box (ray_query.h) on four boxes at once, with the same
///     operations and the same conservative far distance, so a box the scalar test enters is
///     entered here. Closest hit: hit children in order of their entry distance, the nearest
///     first; any hit: in any order, stopping at the first.
///   - Packets (intersect4 / intersect8, wide_bvh_packet.inl): lanes that share their direction
///     signs and ray space test the four child boxes together and a leaf's triangles one at a
///     time against all lanes; other packets walk it lane by lane.
///   - Used for the static set of `native-bvh` (single rays and camera packets) and for the BVHs
///     of meshes that rigid instances share (every native backend; single rays), both built once
///     and never refitted; deforming meshes' BVHs (refitted every frame) keep the binary tree.

#include "specula/accel/bvh/bvh.h"
#include "specula/accel/common/ray_query.h"

#include <cstdint>
#include <span>
#include <vector>

namespace specula::accel {

/// One node: four child boxes in SoA, and each child's reference. count[i] == 0: interior child,
/// node child[i]; count[i] > 0: a leaf of count[i] groups of triangles from child[i] of the group
/// array. An unused slot has an empty box (lo = +inf, hi = -inf), which no ray enters, and count 0.
struct alignas(16) WideBvhNode {
  float lo[3][4];
  float hi[3][4];
  std::uint32_t child[4];
  std::uint32_t count[4];
};
static_assert(sizeof(WideBvhNode) == 128);

/// Up to four triangles of a leaf: p[vertex][axis][lane]; prim[lane] indexes the TriangleView,
/// 0xFFFFFFFF in an unused lane (whose vertices are NaN: no test passes).
struct alignas(16) WideTriangles {
  float p[3][3][4];
  std::uint32_t prim[4];
};
static_assert(sizeof(WideTriangles) == 160);

struct WideBvhStats {
  std::uint32_t nodes = 0, leaves = 0, max_depth = 0;
  std::uint32_t empty_slots = 0; ///< child slots left unused (binary leaves under a node)
  std::uint32_t groups = 0;      ///< WideTriangles records
  std::uint64_t triangles = 0;   ///< triangle references over all groups
  std::size_t bytes = 0;
};

class WideBvh {
public:
  /// Collapses `binary` (expanded first if it is lazy), a tree over the triangles of `tris`, and
  /// copies the leaves' triangles (hits report indices into `tris`, which is not kept). An empty
  /// tree gives an empty WideBvh.
  void build(const Bvh& binary, const TriangleView& tris);

  [[nodiscard]] bool empty() const { return nodes_.empty(); }

  /// Closest hit: on a hit closer than r.tfar updates `hit`, sets r.tfar = hit.t, returns true.
  bool intersect(PreparedRay& r, TriangleHit& hit,
                 TriangleTest test = TriangleTest::watertight) const;
  /// Whether any triangle lies within (r.tnear, r.tfar).
  [[nodiscard]] bool occluded(const PreparedRay& r,
                              TriangleTest test = TriangleTest::watertight) const;

  /// Packets: lanes with active[i] == false are ignored; a lane's hit and tfar are written only
  /// where a hit closer than rays.tfar[i] is found. Lanes that share their direction signs and
  /// their ray space (camera packets) walk the tree together (wide_bvh_packet.inl); others, and
  /// the Möller–Trumbore option, each walk it as a single ray. A lane's closest hit is its
  /// single ray's (where two triangles meet, their hits an ulp or so apart, the other one may
  /// win). intersect8 uses AVX2 where the CPU has it, else two packets of four.
  void intersect4(RayPacket<4>& rays, PacketHits<4>& hits, const bool active[4],
                  TriangleTest test = TriangleTest::watertight) const;
  void intersect8(RayPacket<8>& rays, PacketHits<8>& hits, const bool active[8],
                  TriangleTest test = TriangleTest::watertight) const;

  /// Occlusion of a packet: the mask of active lanes whose ray meets a triangle within (tnear,
  /// tfar), each lane's answer occluded()'s for its ray. Lanes that share their direction signs
  /// and their ray space walk the tree together, each leaving it once blocked; others (and the
  /// Möller–Trumbore option) walk it one by one. occluded8 uses AVX2 where the CPU has it, else
  /// two packets of four.
  [[nodiscard]] unsigned occluded4(const RayPacket<4>& rays, const bool active[4],
                                   TriangleTest test = TriangleTest::watertight) const;
  [[nodiscard]] unsigned occluded8(const RayPacket<8>& rays, const bool active[8],
                                   TriangleTest test = TriangleTest::watertight) const;

  [[nodiscard]] std::span<const WideBvhNode> nodes() const { return nodes_; }
  [[nodiscard]] std::span<const WideTriangles> groups() const { return groups_; }
  [[nodiscard]] const WideBvhStats& stats() const { return stats_; }

  /// Entries of the traversal stack: at most three pushed per level, and the binary tree's depth
  /// is below Bvh::kSahDepthLimit + 33 (build() checks the collapsed depth against it).
  static constexpr int kStackSize = 256;

private:
  /// From the root, or from the subtree (start_child, start_count) as a WideBvhNode's child
  /// entry gives it.
  template <TriangleTest Test, bool AnyHit>
  bool traverse(PreparedRay& r, TriangleHit* hit, std::uint32_t start_child = 0,
                std::uint32_t start_count = 0) const;
  template <int N, TriangleTest Test>
  unsigned occluded_packet(const RayPacket<N>& rays, const bool* active, TestTag<Test>) const;
  template <int N, TriangleTest Test>
  void intersect_packet(RayPacket<N>& rays, PacketHits<N>& hits, const bool* active,
                        TestTag<Test>) const;

  std::vector<WideBvhNode> nodes_;
  std::vector<WideTriangles> groups_;
  WideBvhStats stats_;
};

} // namespace specula::accel
