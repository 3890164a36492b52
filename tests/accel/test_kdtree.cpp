// The SAH kd-tree (engine/accel/kdtree): hits against the brute-force reference, any-hit, packets,
// the tree's structural invariants, a deterministic parallel build, the O(N log N) work bound, and
// rays and triangles that must not break anything.
#include "specula/accel/kdtree/kdtree.h"

#include "accel_test_meshes.h"
#include "packet_occlusion_check.h"

#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

using namespace specula;
using namespace specula::accel;

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

using test::kBruteForceDivisor;
using test::Mesh;
using test::cube;
using test::uv_sphere;

/// n triangles of about `size` with centres uniform in [-1, 1]^3.
Mesh soup(std::uint32_t n, float size, std::uint32_t seed) {
  return test::random_soup(int(n), seed, 1.0f, size);
}

/// A k × k grid of unit squares in the plane z = 0 (the scene's box is flat).
Mesh flat_grid(int k) { return test::flat_grid(k, k, 0.0f, float(k)); }

/// A sphere plus zero-area triangles (points, repeated vertices, segments, collinear vertices),
/// needles, slivers, slivers in the top plane of the sphere's box, and triangles with a NaN or an
/// infinite vertex.
Mesh degenerate_mesh() {
  Mesh m = uv_sphere(16, 24, 1.0f, vec3(0.0f));
  m.name = "degenerate";
  test::add_degenerate_triangles(m, 600, 77, 1.0f, 1.0f);
  m.add(vec3(0.0f), vec3(kNaN, 0.0f, 0.0f), vec3(1.0f));
  return m;
}

struct RaySet {
  std::vector<PreparedRay> rays;
};

/// Half the rays from one point towards random points of the (enlarged) box, half with random
/// origins and directions.
std::vector<PreparedRay> make_rays(const Aabb& box, int count, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  std::normal_distribution<float> normal;
  const vec3 lo = box.min - 0.25f * (box.extent() + vec3(1.0f));
  const vec3 hi = box.max + 0.25f * (box.extent() + vec3(1.0f));
  auto inside = [&] { return lo + (hi - lo) * vec3(unit(rng), unit(rng), unit(rng)); };
  const vec3 eye = box.center() + vec3(0.3f, 0.7f, 2.5f) * (box.extent() + vec3(1.0f));
  std::vector<PreparedRay> rays;
  for (int i = 0; i < count; ++i) {
    if (i % 2 == 0) {
      rays.push_back(PreparedRay::make(eye, inside() - eye, 0.0f, kInf));
    } else {
      vec3 d(normal(rng), normal(rng), normal(rng));
      if (d == vec3(0.0f)) d = vec3(0, 0, 1);
      rays.push_back(PreparedRay::make(inside(), d, 0.0f, i % 7 == 1 ? 2.0f : kInf));
    }
  }
  return rays;
}

bool same_hit(const TriangleHit& got, const TriangleHit& want) {
  if (got.hit() != want.hit()) return false;
  if (!got.hit()) return true;
  if (got.prim == want.prim) return got.t == want.t && got.u == want.u && got.v == want.v;
  return std::abs(got.t - want.t) <= 1e-5f * std::max(1.0f, std::abs(want.t));
}

template <TriangleTest Test>
void check_against_brute_force(const Mesh& mesh, const std::vector<PreparedRay>& rays) {
  KdTree tree;
  tree.build(mesh.view());
  const TriangleView tris = mesh.view();
  int wrong = 0, hits = 0, occlusion_wrong = 0;
  for (const PreparedRay& ray : rays) {
    const TriangleHit want = brute_force_closest<Test>(tris, ray);
    PreparedRay r = ray;
    TriangleHit got;
    const bool hit = tree.intersect(r, got, Test);
    hits += want.hit();
    const bool ok = hit == got.hit() && same_hit(got, want) && (!hit || r.tfar == got.t);
    if (!ok && ++wrong <= 5) {
      ADD_FAILURE() << mesh.name << ": ray o=(" << ray.org.x << ", " << ray.org.y << ", "
                    << ray.org.z << ") d=(" << ray.dir.x << ", " << ray.dir.y << ", " << ray.dir.z
                    << ") kd prim " << got.prim << " t " << got.t << ", reference prim "
                    << want.prim << " t " << want.t;
    }
    if (tree.occluded(ray, Test) != want.hit()) ++occlusion_wrong;
  }
  EXPECT_EQ(wrong, 0) << mesh.name << " over " << rays.size() << " rays";
  EXPECT_EQ(occlusion_wrong, 0) << mesh.name;
  EXPECT_GT(hits, int(rays.size()) / 20) << mesh.name << ": the rays should mostly hit something";
}

/// Seeded axis-aligned boxes with corners on an integer lattice: every triangle lies in an axis
/// plane shared with other boxes' faces, so the sweep's best planes often hold triangles, and cuts
/// off empty space (told from the ends of the axis's list, without classifying) fall on them with
/// the planar triangles sent either way.
Mesh box_lattice() {
  Mesh m{"box lattice", {}, {}};
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> corner(0, 7), size(0, 3);
  const Mesh unit = cube();
  for (int b = 0; b < 60; ++b) {
    const vec3 lo(float(corner(rng)), float(corner(rng)), float(corner(rng)));
    // A size of 0 on an axis makes a flat box: its triangles lie in the one plane twice over.
    const vec3 hi = lo + vec3(float(size(rng)), float(size(rng)), float(size(rng)));
    const auto base = std::uint32_t(m.positions.size());
    for (const vec3& c : unit.positions) m.positions.push_back(lo + 0.5f * (c + 1.0f) * (hi - lo));
    for (const uvec3& t : unit.triangles) m.triangles.push_back(t + uvec3(base));
  }
  return m;
}

std::vector<Mesh> test_meshes() {
  // The dense soup's large, crossing triangles straddle many cells: hits found in a cell often lie
  // beyond it, which is what the traversal's termination must get right.
  Mesh dense = soup(1500, 0.6f, 12);
  dense.name = "dense soup";
  return {uv_sphere(24, 48, 1.0f, vec3(0.5f, -0.25f, 2.0f)),
          cube(),
          soup(2000, 0.08f, 11),
          std::move(dense),
          flat_grid(24),
          box_lattice(),
          degenerate_mesh()};
}

/// Calls f(node, box, depth) on every node in depth-first order, checking that the order of
/// the array is that order.
template <class F>
void walk(const KdTree& tree, F&& f) {
  std::uint32_t expected = 0;
  auto rec = [&](auto&& self, std::uint32_t node, const Aabb& box, std::uint32_t depth) -> void {
    ASSERT_EQ(node, expected) << "nodes are not in depth-first order";
    ++expected;
    const gpu::KdNode n = tree.nodes()[node];
    f(node, box, depth);
    if ((n.bits & 3u) == gpu::kKdLeaf) return;
    const int axis = int(n.bits & 3u);
    Aabb below = box, above = box;
    below.max[axis] = n.split;
    above.min[axis] = n.split;
    self(self, node + 1, below, depth + 1);
    ASSERT_EQ(n.bits >> 2, expected) << "the child above does not follow the subtree below";
    self(self, n.bits >> 2, above, depth + 1);
  };
  rec(rec, 0, tree.bounds(), 0);
  EXPECT_EQ(expected, tree.nodes().size());
}

bool same_tree(const KdTree& a, const KdTree& b) {
  return a.nodes().size() == b.nodes().size() && a.indices().size() == b.indices().size() &&
         std::memcmp(a.nodes().data(), b.nodes().data(), a.nodes().size_bytes()) == 0 &&
         std::equal(a.indices().begin(), a.indices().end(), b.indices().begin());
}

template <int N>
RayPacket<N> pack(const std::vector<PreparedRay>& rays, std::size_t first) {
  RayPacket<N> p;
  for (int i = 0; i < N; ++i) {
    const PreparedRay& r = rays[(first + std::size_t(i)) % rays.size()];
    p.ox[i] = r.org.x, p.oy[i] = r.org.y, p.oz[i] = r.org.z;
    p.dx[i] = r.dir.x, p.dy[i] = r.dir.y, p.dz[i] = r.dir.z;
    p.tnear[i] = r.tnear, p.tfar[i] = r.tfar;
  }
  return p;
}

template <int N>
void check_packets(const Mesh& mesh, const std::vector<PreparedRay>& rays, bool coherent_only,
                   TriangleTest test = TriangleTest::watertight) {
  KdTree tree;
  tree.build(mesh.view());
  std::mt19937 rng(1234);
  int wrong = 0, lanes = 0;
  // Coherent: the even rays (all from one eye). Mixed: consecutive rays of both kinds.
  std::vector<PreparedRay> source;
  for (std::size_t i = 0; i < rays.size(); ++i)
    if (!coherent_only || i % 2 == 0) source.push_back(rays[i]);
  // Packets of neighbouring camera rays share their signs: sort the eye rays by direction.
  if (coherent_only) {
    std::sort(source.begin(), source.end(), [](const PreparedRay& a, const PreparedRay& b) {
      return std::make_tuple(a.neg[0], a.neg[1], a.neg[2], a.dir.x) <
             std::make_tuple(b.neg[0], b.neg[1], b.neg[2], b.dir.x);
    });
  }
  for (std::size_t first = 0; first < source.size(); first += N) {
    RayPacket<N> packet = pack<N>(source, first);
    const RayPacket<N> original = packet;
    bool active[N];
    for (int i = 0; i < N; ++i) active[i] = rng() % 5 != 0;
    PacketHits<N> hits;
    hits.clear();
    for (int i = 0; i < N; ++i) hits.u[i] = -7.0f; // a marker: untouched lanes keep it
    if constexpr (N == 4)
      tree.intersect4(packet, hits, active, test);
    else
      tree.intersect8(packet, hits, active, test);
    for (int i = 0; i < N; ++i) {
      ++lanes;
      PreparedRay r = source[(first + std::size_t(i)) % source.size()];
      TriangleHit want;
      if (active[i]) tree.intersect(r, want, test);
      TriangleHit got;
      got.prim = hits.prim[i];
      got.t = hits.t[i];
      got.u = hits.u[i];
      got.v = hits.v[i];
      // The same hit to the bit: a lane walks the cells its single ray walks, in the same order
      // (the lanes share their signs), over the same intervals, with the same triangle tests
      // (NativeTracer's intersect batches rely on it: a ray's hit must not depend on the rays
      // packed beside it).
      bool ok = got.prim == want.prim &&
                (!want.hit() || (got.t == want.t && got.u == want.u && got.v == want.v)) &&
                packet.tfar[i] == (want.hit() ? got.t : original.tfar[i]);
      if (!want.hit()) ok = ok && got.u == -7.0f;
      if (!ok && ++wrong <= 5)
        ADD_FAILURE() << mesh.name << " packet " << N << " lane " << i << " active " << active[i]
                      << ": prim " << got.prim << " t " << got.t << ", single ray prim "
                      << want.prim << " t " << want.t;
    }
  }
  EXPECT_EQ(wrong, 0) << mesh.name << " over " << lanes << " lanes";
}

} // namespace

TEST(KdTree, ClosestHitMatchesBruteForce) {
  int total = 0;
  for (const Mesh& mesh : test_meshes()) {
    Aabb box;
    for (const vec3& p : mesh.positions)
      if (is_finite(p)) box.grow(p);
    const auto rays = make_rays(box, 24000 / kBruteForceDivisor, 99);
    total += int(rays.size());
    check_against_brute_force<TriangleTest::watertight>(mesh, rays);
  }
  EXPECT_GE(total, 100000 / kBruteForceDivisor);
}

TEST(KdTree, ClosestHitMatchesBruteForceWithMollerTrumbore) {
  for (const Mesh& mesh : test_meshes()) {
    Aabb box;
    for (const vec3& p : mesh.positions)
      if (is_finite(p)) box.grow(p);
    check_against_brute_force<TriangleTest::moller_trumbore>(mesh, make_rays(box, 6000, 5));
  }
}

// Rays aimed exactly at the grid's vertices and edges: a split plane through every vertex line,
// and hits on the planes themselves. The kd-tree must find a hit wherever the reference does.
TEST(KdTree, RaysThroughSplitPlanesAndSharedEdges) {
  const Mesh grid = flat_grid(16);
  const Mesh box = cube();
  std::vector<PreparedRay> rays;
  for (int y = 0; y <= 32; ++y) {
    for (int x = 0; x <= 32; ++x) {
      const vec3 target(float(x) * 0.5f, float(y) * 0.5f, 0.0f);
      rays.push_back(
          PreparedRay::make(vec3(3.3f, 7.1f, 5.0f), target - vec3(3.3f, 7.1f, 5.0f), 0.0f, kInf));
      rays.push_back(PreparedRay::make(target + vec3(0, 0, 1), vec3(0, 0, -1), 0.0f, kInf));
      // In the plane of the grid, along its lines: parallel to every triangle, so no hit.
      rays.push_back(
          PreparedRay::make(vec3(-1.0f, float(y) * 0.5f, 0.0f), vec3(1, 0, 0), 0.0f, kInf));
    }
  }
  check_against_brute_force<TriangleTest::watertight>(grid, rays);
  std::vector<PreparedRay> cube_rays;
  for (int i = -8; i <= 8; ++i)
    for (int j = -8; j <= 8; ++j) {
      const vec3 o(float(i) * 0.25f, float(j) * 0.25f, 3.0f);
      cube_rays.push_back(PreparedRay::make(o, vec3(0, 0, -1), 0.0f, kInf));
      cube_rays.push_back(
          PreparedRay::make(vec3(0.0f), vec3(float(i), float(j), 4.0f), 0.0f, kInf));
    }
  check_against_brute_force<TriangleTest::watertight>(box, cube_rays);
}

// Vertices and ray origins on a 1/8 lattice, directions with zero components: triangles lie in
// split planes and rays run inside them, where both children cover the same stretch of the ray
// and the traversal stack is not sorted by distance.
TEST(KdTree, RaysLyingInSplitPlanes) {
  Mesh lattice{"lattice soup", {}, {}};
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  auto snap = [](const vec3& p) { return glm::round(p * 8.0f) / 8.0f; };
  for (int i = 0; i < 800; ++i) {
    const vec3 c(unit(rng), unit(rng), unit(rng));
    lattice.add(snap(c + 0.15f * vec3(unit(rng), unit(rng), unit(rng))),
                snap(c + 0.15f * vec3(unit(rng), unit(rng), unit(rng))),
                snap(c + 0.15f * vec3(unit(rng), unit(rng), unit(rng))));
  }
  std::vector<PreparedRay> rays;
  for (int i = 0; i < 20000; ++i) {
    const vec3 o = snap(1.2f * vec3(unit(rng), unit(rng), unit(rng)));
    vec3 d = glm::round(vec3(unit(rng), unit(rng), unit(rng)) * 1.5f); // components in {-1, 0, 1}
    if (d == vec3(0.0f)) d = vec3(0.0f, -1.0f, 0.0f);
    if (i % 2 == 1) d[i % 3] = -0.0f; // the sign of zero picks the side that comes first
    rays.push_back(PreparedRay::make(o, d, 0.0f, kInf));
  }
  check_against_brute_force<TriangleTest::watertight>(lattice, rays);
  check_packets<4>(lattice, rays, false);
  check_packets<8>(lattice, rays, false);
}

// Single rays test a leaf's triangles four at a time (SSE lanes over triangles) where it holds
// three or more. The lanes must give what the scalar test gives one triangle at a time, to the bit:
// the same triangle (the first in the leaf's order at equal distance: here exact duplicates), the
// same t, u and v, the same any-hit answer, also for rays aimed at vertices (an edge function of
// exactly 0 sends the group to the scalar test's double fallback). Shallow trees with large leaves
// put every size of group, and groups with a scalar tail, on the rays' way.
TEST(KdTree, LeavesTestedFourAtATimeMatchTheScalarTestBitForBit) {
  Mesh mesh = soup(700, 0.35f, 61);
  mesh.name = "soup with duplicates";
  for (std::uint32_t i = 0; i < 150; ++i) mesh.triangles.push_back(mesh.triangles[3 * i]);
  const TriangleView view = mesh.view();
  std::vector<PreparedRay> rays = make_rays(mesh.bounds(), 6000, 62);
  std::mt19937 rng(63);
  std::uniform_int_distribution<std::uint32_t> pick(0, std::uint32_t(mesh.positions.size()) - 1);
  const vec3 eye = mesh.bounds().center() + vec3(0.4f, 2.5f, 3.0f);
  for (int i = 0; i < 3000; ++i) {
    const vec3 target = mesh.positions[pick(rng)];
    rays.push_back(PreparedRay::make(eye, target - eye, 0.0f, kInf));
  }
  // Leaves of every group shape over the three trees: 3 and 4 triangles (one group), 5 to 7 (a
  // group and a scalar tail), 8 or more (several groups).
  std::array<int, 9> leaves_of{};
  for (const auto& [leaf_size, max_depth] : {std::pair{6u, 10u}, {12u, 8u}, {40u, 5u}}) {
    SCOPED_TRACE("leaf size " + std::to_string(leaf_size));
    KdTree tree;
    KdBuildOptions options;
    options.leaf_size = leaf_size;
    options.max_depth = max_depth;
    tree.build(view, options);
    for (const gpu::KdNode& n : tree.nodes())
      if ((n.bits & 3u) == gpu::kKdLeaf) ++leaves_of[std::min<std::size_t>(n.bits >> 2, 8)];
    int wrong = 0, hits = 0, occlusion_wrong = 0;
    for (const PreparedRay& ray : rays) {
      const TriangleHit want = brute_force_closest(view, ray);
      PreparedRay r = ray;
      TriangleHit got;
      tree.intersect(r, got);
      hits += want.hit();
      const bool ok = got.prim == want.prim &&
                      std::bit_cast<std::uint32_t>(got.t) == std::bit_cast<std::uint32_t>(want.t) &&
                      std::bit_cast<std::uint32_t>(got.u) == std::bit_cast<std::uint32_t>(want.u) &&
                      std::bit_cast<std::uint32_t>(got.v) == std::bit_cast<std::uint32_t>(want.v);
      if (!ok && ++wrong <= 5)
        ADD_FAILURE() << "kd prim " << got.prim << " t " << got.t << ", reference prim "
                      << want.prim << " t " << want.t;
      occlusion_wrong += tree.occluded(ray) != want.hit();
    }
    EXPECT_EQ(wrong, 0);
    EXPECT_EQ(occlusion_wrong, 0);
    EXPECT_GT(hits, int(rays.size()) / 4);
  }
  for (std::size_t c = 3; c <= 8; ++c) EXPECT_GT(leaves_of[c], 0) << c << " triangles";
}

TEST(KdTree, PacketsMatchSingleRays) {
  for (const Mesh& mesh : test_meshes()) {
    Aabb box;
    for (const vec3& p : mesh.positions)
      if (is_finite(p)) box.grow(p);
    const auto rays = make_rays(box, 8000, 4242);
    check_packets<4>(mesh, rays, true);
    check_packets<4>(mesh, rays, false);
    check_packets<8>(mesh, rays, true);
    check_packets<8>(mesh, rays, false);
    check_packets<4>(mesh, rays, true, TriangleTest::moller_trumbore);
    check_packets<8>(mesh, rays, false, TriangleTest::moller_trumbore);
  }
}

TEST(KdTree, PacketOcclusionEqualsSingleRaysPerLane) {
  for (const Mesh& mesh : test_meshes()) {
    SCOPED_TRACE(mesh.name);
    const TriangleView view = mesh.view();
    KdTree tree;
    tree.build(view);
    Aabb box;
    for (const vec3& p : mesh.positions)
      if (is_finite(p)) box.grow(p);
    test::expect_occlusion_packets_match(tree, view, box, 331);
  }
}

TEST(KdTree, CameraPacketMatchesReference) {
  // A camera-like packet: every lane from one eye into the sphere, all directions with the same
  // signs, plus one lane that misses and one with an invalid direction.
  const Mesh sphere = uv_sphere(24, 48, 1.0f, vec3(0.0f));
  KdTree tree;
  tree.build(sphere.view());
  RayPacket<8> p;
  const bool active[8] = {true, true, true, true, true, true, true, true};
  for (int i = 0; i < 8; ++i) {
    p.ox[i] = -3.0f, p.oy[i] = -3.0f, p.oz[i] = -3.0f;
    p.dx[i] = 1.0f + 0.02f * float(i), p.dy[i] = 1.0f, p.dz[i] = 1.0f - 0.01f * float(i);
    p.tnear[i] = 0.0f, p.tfar[i] = kInf;
  }
  p.dx[6] = 1.0f, p.dy[6] = 0.05f, p.dz[6] = 0.05f; // passes beside the sphere
  p.dx[7] = 0.0f, p.dy[7] = 0.0f, p.dz[7] = 0.0f;   // invalid
  PacketHits<8> hits;
  hits.clear();
  tree.intersect8(p, hits, active);
  for (int i = 0; i < 8; ++i) {
    PreparedRay r = PreparedRay::make(vec3(p.ox[i], p.oy[i], p.oz[i]),
                                      vec3(p.dx[i], p.dy[i], p.dz[i]), 0.0f, kInf);
    const TriangleHit want = brute_force_closest(sphere.view(), r);
    EXPECT_EQ(hits.prim[i], want.prim) << "lane " << i;
    if (want.hit()) {
      EXPECT_EQ(hits.t[i], want.t);
    }
  }
  EXPECT_EQ(hits.prim[6], 0xFFFFFFFFu);
  EXPECT_EQ(hits.prim[7], 0xFFFFFFFFu);
}

TEST(KdTree, StructuralInvariants) {
  for (const Mesh& mesh : test_meshes()) {
    KdTree tree;
    tree.build(mesh.view());
    const TriangleView tris = mesh.view();
    ASSERT_FALSE(tree.empty());
    std::vector<std::vector<std::uint32_t>> leaves_of(tris.count);
    std::vector<Aabb> leaf_boxes;
    std::uint32_t leaves = 0, max_depth = 0;
    std::uint64_t references = 0;
    walk(tree, [&](std::uint32_t node, const Aabb& box, std::uint32_t depth) {
      const gpu::KdNode n = tree.nodes()[node];
      max_depth = std::max(max_depth, depth);
      if ((n.bits & 3u) != gpu::kKdLeaf) {
        // A split lies in the box; on one of its faces only to cut off the triangles lying in
        // that face into a flat cell, which needs an axis the box has extent on.
        const int axis = int(n.bits & 3u);
        EXPECT_GE(n.split, box.min[axis]) << mesh.name << " node " << node;
        EXPECT_LE(n.split, box.max[axis]) << mesh.name << " node " << node;
        EXPECT_LT(box.min[axis], box.max[axis]) << mesh.name << " node " << node;
        return;
      }
      ++leaves;
      const std::uint32_t count = n.bits >> 2;
      references += count;
      ASSERT_LE(std::uint64_t(n.first) + count, tree.indices().size());
      for (std::uint32_t k = 0; k < count; ++k) {
        const std::uint32_t prim = tree.indices()[n.first + k];
        ASSERT_LT(prim, tris.count);
        // A leaf holds only triangles that reach its cell (a clipped box padded past its
        // triangle once let a sliver's triangle through a plane beyond it, into both children).
        const Aabb tb = tris.bounds(prim);
        EXPECT_TRUE(glm::all(glm::lessThanEqual(tb.min, box.max)) &&
                    glm::all(glm::lessThanEqual(box.min, tb.max)))
            << mesh.name << ": leaf " << node << " references triangle " << prim
            << ", which lies outside its cell";
        leaves_of[prim].push_back(std::uint32_t(leaf_boxes.size()));
      }
      leaf_boxes.push_back(box);
    });
    EXPECT_EQ(leaves, tree.stats().leaves);
    EXPECT_EQ(references, tree.stats().leaf_references);
    EXPECT_EQ(references, tree.indices().size());
    EXPECT_EQ(max_depth, tree.stats().max_depth);
    EXPECT_EQ(tree.stats().bytes, tree.nodes().size_bytes() + tree.indices().size_bytes());
    // Every finite triangle is referenced, and the leaves referencing it cover its points: its
    // vertices and centroid each lie in (the closure of) one of them.
    for (std::uint32_t prim = 0; prim < tris.count; ++prim) {
      const vec3 p[3] = {tris.vertex(prim, 0), tris.vertex(prim, 1), tris.vertex(prim, 2)};
      if (!is_finite(p[0]) || !is_finite(p[1]) || !is_finite(p[2])) {
        EXPECT_TRUE(leaves_of[prim].empty()) << mesh.name << ": a NaN triangle is referenced";
        continue;
      }
      ASSERT_FALSE(leaves_of[prim].empty()) << mesh.name << " triangle " << prim;
      // (The centroid is clamped to the triangle's box: a flat axis keeps its exact value.)
      const Aabb tb = tris.bounds(prim);
      const vec3 centroid = glm::clamp((p[0] + p[1] + p[2]) / 3.0f, tb.min, tb.max);
      const vec3 points[4] = {p[0], p[1], p[2], centroid};
      for (const vec3& q : points) {
        bool covered = false;
        for (std::uint32_t leaf : leaves_of[prim]) {
          const Aabb& b = leaf_boxes[leaf];
          covered = covered || (glm::all(glm::greaterThanEqual(q, b.min)) &&
                                glm::all(glm::lessThanEqual(q, b.max)));
        }
        EXPECT_TRUE(covered) << mesh.name << " triangle " << prim;
      }
    }
  }
}

// A floor that is the bottom face of the scene's box (a ground plane, a Cornell box's walls): the
// only planes that cut it off from the space above lie in that face, so the sweep must consider
// them. Without them every cell along the floor, however tall, keeps the floor's triangles and a
// ray crossing those cells tests them again and again.
TEST(KdTree, TrianglesLyingInAFaceOfTheBoxGetAFlatCell) {
  Mesh scene = test::flat_grid(16, 16, -8.0f, 8.0f, 0.0f); // the floor: z = 0, 512 triangles
  const auto floor_triangles = std::uint32_t(scene.triangles.size());
  const Mesh ball = uv_sphere(12, 24, 1.0f, vec3(0.0f, 0.0f, 2.0f)); // z in [1, 3]
  const auto base = std::uint32_t(scene.positions.size());
  scene.positions.insert(scene.positions.end(), ball.positions.begin(), ball.positions.end());
  for (const uvec3& t : ball.triangles) scene.triangles.push_back(t + uvec3(base));
  scene.name = "floor and ball";
  KdTree tree;
  tree.build(scene.view());
  ASSERT_EQ(tree.bounds().min.z, 0.0f);
  std::uint32_t floor_references = 0, raised = 0;
  walk(tree, [&](std::uint32_t node, const Aabb& box, std::uint32_t) {
    const gpu::KdNode n = tree.nodes()[node];
    if ((n.bits & 3u) != gpu::kKdLeaf) return;
    for (std::uint32_t k = 0; k < (n.bits >> 2); ++k) {
      if (tree.indices()[n.first + k] >= floor_triangles) continue;
      ++floor_references;
      if (box.max.z > 0.0f) ++raised;
    }
  });
  EXPECT_GE(floor_references, floor_triangles);
  EXPECT_EQ(raised, 0u) << "floor triangles referenced by cells that rise above the floor";
  // And rays still find the floor and the ball as brute force does.
  check_against_brute_force<TriangleTest::watertight>(scene, make_rays(scene.bounds(), 4000, 41));
}

// Far from the origin a sphere of radius 1 spans ~128 ulps, and a plane a fraction of an ulp from
// a vertex clips off a corner of its triangles thinner than an ulp. Its clipped box then rounds to
// a flat box in the cell's face; it used to go to a flat cell of its own, and rays crossing the
// sliver inside the cell missed the triangle (found by the robustness suite at 1e5: a ray passed
// through the sphere's top). Rays aimed at the vertices, where the slivers are, against brute force.
TEST(KdTree, SliversThinnerThanAnUlpStayInTheirCells) {
  for (const float offset : {1e4f, 1e5f, 1e6f}) {
    const vec3 centre(offset, offset, -offset);
    Mesh mesh = uv_sphere(24, 48, 1.0f, centre);
    mesh.name = "sphere at " + std::to_string(offset);
    std::mt19937 rng(23);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    std::uniform_int_distribution<std::size_t> vertex(0, mesh.positions.size() - 1);
    std::vector<PreparedRay> rays;
    const int count = 20000 / kBruteForceDivisor;
    for (int i = 0; i < count; ++i) {
      vec3 d(0.0f);
      while (glm::length(d) < 0.1f) {
        const float x = unit(rng), y = unit(rng), z = unit(rng);
        d = vec3(x, y, z);
      }
      const vec3 origin = centre + 4.0f * glm::normalize(d);
      const vec3 target = mesh.positions[vertex(rng)];
      rays.push_back(PreparedRay::make(origin, target - origin, 0.0f, kInf));
    }
    check_against_brute_force<TriangleTest::watertight>(mesh, rays);
  }
}

// A cut with one side empty hands the node's own event lists to the other child instead of
// filtering them. Here the root holds a dense sphere and one far-off triangle, so the first cuts
// are one-sided and large (lists on the heap, children built as parallel tasks): the tree must
// still find every hit brute force finds, on one thread and two alike.
TEST(KdTree, OneSidedCutsOfLargeNodesKeepEveryTriangle) {
  Mesh mesh = uv_sphere(48, 96, 1.0f, vec3(0.0f));
  mesh.name = "sphere and a far triangle";
  mesh.add(vec3(40.0f, 40.0f, 40.0f), vec3(40.5f, 40.0f, 40.0f), vec3(40.0f, 40.5f, 40.0f));
  KdTree one, two;
  tbb::task_arena(2).execute([&] { two.build(mesh.view()); });
  tbb::task_arena(1).execute([&] { one.build(mesh.view()); });
  EXPECT_TRUE(same_tree(one, two));
  // Find a one-sided cut near the root whose full side holds most of the mesh.
  std::uint32_t large_one_sided = 0;
  std::vector<std::uint32_t> subtree_refs(one.nodes().size(), 0);
  for (std::size_t i = one.nodes().size(); i-- > 0;) {
    const gpu::KdNode n = one.nodes()[i];
    if ((n.bits & 3u) == gpu::kKdLeaf) {
      subtree_refs[i] = n.bits >> 2;
      continue;
    }
    const std::uint32_t below = std::uint32_t(i) + 1, above = n.bits >> 2;
    subtree_refs[i] = subtree_refs[below] + subtree_refs[above];
    const bool below_empty = subtree_refs[below] == 0, above_empty = subtree_refs[above] == 0;
    if ((below_empty || above_empty) && subtree_refs[i] >= 2048) ++large_one_sided;
  }
  EXPECT_GE(large_one_sided, 1u) << "the mesh should make the tree cut off empty space early";
  // Rays at the sphere, rays anywhere, and rays aimed at the far triangle.
  std::vector<PreparedRay> rays = make_rays(Aabb{vec3(-1.0f), vec3(1.0f)}, 3000, 91);
  const std::vector<PreparedRay> wide = make_rays(mesh.bounds(), 1000, 92);
  rays.insert(rays.end(), wide.begin(), wide.end());
  std::mt19937 rng(93);
  std::uniform_real_distribution<float> unit(0.0f, 0.15f);
  for (int i = 0; i < 200; ++i) {
    const vec3 target(40.0f + unit(rng), 40.0f + unit(rng), 40.0f);
    rays.push_back(
        PreparedRay::make(vec3(0.0f, 0.0f, 5.0f), target - vec3(0.0f, 0.0f, 5.0f), 0.0f, kInf));
  }
  check_against_brute_force<TriangleTest::watertight>(mesh, rays);
}

// With AVX2 the build sweeps long event lists eight events at a time (per lane the counts by type
// as prefix sums, whether the event is its position's last, the counts before the position as a
// max-scan, the costs, and each lane's first best, reduced in list order), and builds nodes of at
// most 16 triangles from their boxes (every start and end of a box a candidate lane, its counts
// taken over the triangles, the first best in the scalar sweep's order). Both must choose the
// scalar sweep's plane every time, ties and all, or the trees differ: positions shared by many
// triangles (a grid's rows: runs of equal keys across blocks), triangles in split planes and in the
// box's faces (the box lattice, the floor), degenerate triangles, and nodes of every size. The work
// counters must be the event lists' too.
TEST(KdTree, SimdBuildsTheScalarBuildsTree) {
  if (!cpu_has_avx2()) GTEST_SKIP() << "no AVX2: the scalar sweep is the only one";
  std::vector<Mesh> meshes = test_meshes();
  meshes.push_back(soup(20000, 0.05f, 5));
  Mesh floor_and_ball = test::flat_grid(48, 48, -8.0f, 8.0f, 0.0f);
  const Mesh ball = uv_sphere(32, 64, 1.0f, vec3(0.0f, 0.0f, 2.0f));
  const auto base = std::uint32_t(floor_and_ball.positions.size());
  floor_and_ball.positions.insert(floor_and_ball.positions.end(), ball.positions.begin(),
                                  ball.positions.end());
  for (const uvec3& t : ball.triangles) floor_and_ball.triangles.push_back(t + uvec3(base));
  floor_and_ball.name = "floor and ball";
  meshes.push_back(std::move(floor_and_ball));
  // Two equal clusters of 16 triangles, x in [0, 1] and [3, 4], with the same extent on y and z:
  // the planes at x = 1 and x = 3 cost the same to the bit, and their positions' last events
  // (indices 31 and 47 of 64) fall in the same lane of two blocks, so the lane must keep the
  // first (the scalar sweep's strict comparison keeps x = 1).
  auto twin_clusters = [](int per_cluster, const char* name) {
    Mesh m{name, {}, {}};
    for (const float shift : {0.0f, 3.0f})
      for (int i = 0; i < per_cluster; ++i)
        m.add(vec3(shift, 0.0f, 0.0f), vec3(shift + 1.0f, 1.0f, 0.0f),
              vec3(shift + float(i + 1) / float(2 * per_cluster), 0.5f, 1.0f));
    return m;
  };
  const Mesh twins = twin_clusters(16, "twin clusters");
  meshes.push_back(twins);
  // Nodes of up to 16 triangles are built from boxes. With two triangles a cluster the planes at
  // x = 1 and x = 3 tie in two lanes of one vector; with eight, in one lane of two vectors, the
  // one at x = 3 weighed first (the starts before the ends).
  const Mesh small_twins = twin_clusters(2, "twin clusters of two");
  meshes.push_back(small_twins);
  const Mesh eight_twins = twin_clusters(8, "twin clusters of eight");
  meshes.push_back(eight_twins);
  for (const Mesh& mesh : meshes) {
    KdBuildOptions scalar;
    scalar.simd = false;
    KdTree simd, reference;
    simd.build(mesh.view());
    reference.build(mesh.view(), scalar);
    EXPECT_TRUE(same_tree(simd, reference)) << mesh.name;
    EXPECT_EQ(simd.stats().sah_cost, reference.stats().sah_cost) << mesh.name;
    // The small nodes' boxes count the work their event lists would have.
    EXPECT_EQ(simd.stats().events_processed, reference.stats().events_processed) << mesh.name;
    EXPECT_EQ(simd.stats().sort_work, reference.stats().sort_work) << mesh.name;
    EXPECT_EQ(simd.stats().max_depth, reference.stats().max_depth) << mesh.name;
  }
  for (const Mesh* mesh : {&twins, &small_twins, &eight_twins}) {
    KdTree twin_tree;
    twin_tree.build(mesh->view());
    EXPECT_EQ(twin_tree.nodes()[0].bits & 3u, 0u) << mesh->name << ": the root should split on x";
    EXPECT_EQ(twin_tree.nodes()[0].split, 1.0f) << mesh->name << ": ties go to the first plane";
  }
}

TEST(KdTree, BuildIsDeterministicForAnyThreadCount) {
  const Mesh mesh = soup(40000, 0.03f, 3);
  KdTree one, two, sequential;
  // Two threads first: (this TBB) gives a later arena no worker once an arena of one has run.
  tbb::task_arena(2).execute([&] { two.build(mesh.view()); });
  tbb::task_arena(1).execute([&] { one.build(mesh.view()); });
  KdBuildOptions options;
  options.parallel = false;
  sequential.build(mesh.view(), options);
  EXPECT_GT(one.nodes().size(), 1000u);
  EXPECT_TRUE(same_tree(one, two));
  EXPECT_TRUE(same_tree(one, sequential));
  EXPECT_EQ(one.stats().sah_cost, two.stats().sah_cost);
  EXPECT_EQ(one.stats().events_processed, two.stats().events_processed);
}

// O(N log N), not O(N log² N), without a clock: the per-node passes touch each event a constant
// number of times, so the events they process grow like N log N (the depth grows like log N); and
// the only sort of a size comparable to N is the first one — the later sorts (of the straddling
// triangles' new events) add a bounded fraction to it. A build that re-sorted at every node would
// do sort work ~ N log² N, growing by far more than 4 per quadrupling of N.
TEST(KdTree, BuildWorkGrowsLikeNLogN) {
  std::vector<double> per_nlogn;
  for (std::uint32_t n : {1024u, 4096u, 16384u, 65536u}) {
    // The same scene at every size: triangles shrink as their number grows.
    const Mesh mesh = soup(n, 0.5f / std::cbrt(float(n)), 17);
    KdTree tree;
    tree.build(mesh.view());
    const double nlogn = double(n) * std::log2(double(n));
    per_nlogn.push_back(double(tree.stats().events_processed) / nlogn);
    const double first_sort = 3.0 * 2.0 * double(n) * std::ceil(std::log2(2.0 * double(n)));
    EXPECT_LE(double(tree.stats().sort_work), 1.5 * first_sort) << "n = " << n;
  }
  for (std::size_t i = 1; i < per_nlogn.size(); ++i) {
    // Over 1k → 64k, log2 N grows by 1.6 and so would this ratio for N log² N work.
    EXPECT_LT(per_nlogn[i] / per_nlogn[0], 1.25) << "events per N log N: " << per_nlogn[i];
    EXPECT_GT(per_nlogn[i] / per_nlogn[0], 0.75) << "events per N log N: " << per_nlogn[i];
  }
}

TEST(KdTree, InvalidRaysMiss) {
  const Mesh sphere = uv_sphere(12, 24, 1.0f, vec3(0.0f));
  KdTree tree;
  tree.build(sphere.view());
  const vec3 o(0.0f, 0.0f, -5.0f), d(0.0f, 0.0f, 1.0f);
  const PreparedRay bad[] = {
      PreparedRay::make(vec3(kNaN, 0.0f, -5.0f), d, 0.0f, kInf),
      PreparedRay::make(vec3(0.0f, kInf, -5.0f), d, 0.0f, kInf),
      PreparedRay::make(o, vec3(0.0f, kNaN, 1.0f), 0.0f, kInf),
      PreparedRay::make(o, vec3(0.0f, 0.0f, kInf), 0.0f, kInf),
      PreparedRay::make(o, vec3(0.0f), 0.0f, kInf),
      PreparedRay::make(o, d, kNaN, kInf),
      PreparedRay::make(o, d, 0.0f, kNaN),
      PreparedRay::make(o, d, 3.0f, 2.0f),
      PreparedRay::make(o, d, -1.0f, kInf),
  };
  for (const PreparedRay& ray : bad) {
    PreparedRay r = ray;
    TriangleHit hit;
    EXPECT_FALSE(tree.intersect(r, hit));
    EXPECT_FALSE(hit.hit());
    EXPECT_FALSE(tree.occluded(ray));
    EXPECT_FALSE(tree.intersect(r, hit, TriangleTest::moller_trumbore));
  }
  // The valid ray they were made from hits.
  PreparedRay good = PreparedRay::make(o, d, 0.0f, kInf);
  TriangleHit hit;
  EXPECT_TRUE(tree.intersect(good, hit));
  EXPECT_NEAR(good.tfar, 4.0f, 0.05f);

  // Packets: invalid lanes miss, valid ones hit.
  RayPacket<4> p;
  for (int i = 0; i < 4; ++i) {
    p.ox[i] = 0.0f, p.oy[i] = 0.0f, p.oz[i] = -5.0f;
    p.dx[i] = 0.0f, p.dy[i] = 0.0f, p.dz[i] = 1.0f;
    p.tnear[i] = 0.0f, p.tfar[i] = kInf;
  }
  p.ox[1] = kNaN;
  p.dz[2] = 0.0f;
  p.tnear[3] = 10.0f, p.tfar[3] = 1.0f;
  PacketHits<4> hits;
  hits.clear();
  const bool active[4] = {true, true, true, true};
  tree.intersect4(p, hits, active);
  EXPECT_TRUE(hits.prim[0] != 0xFFFFFFFFu);
  EXPECT_EQ(hits.prim[1], 0xFFFFFFFFu);
  EXPECT_EQ(hits.prim[2], 0xFFFFFFFFu);
  EXPECT_EQ(hits.prim[3], 0xFFFFFFFFu);
}

TEST(KdTree, EmptyAndDegenerateInputs) {
  KdTree tree;
  tree.build(TriangleView{});
  EXPECT_TRUE(tree.empty());
  PreparedRay r = PreparedRay::make(vec3(0.0f), vec3(0, 0, 1), 0.0f, kInf);
  TriangleHit hit;
  EXPECT_FALSE(tree.intersect(r, hit));
  EXPECT_FALSE(tree.occluded(r));
  RayPacket<8> p = pack<8>({r}, 0);
  PacketHits<8> hits;
  hits.clear();
  const bool active[8] = {true, true, true, true, true, true, true, true};
  tree.intersect8(p, hits, active);
  for (std::uint32_t prim : hits.prim) EXPECT_EQ(prim, 0xFFFFFFFFu);

  // Only NaN triangles: an empty tree.
  Mesh nan_only{"nan", {}, {}};
  nan_only.add(vec3(kNaN), vec3(1.0f), vec3(2.0f));
  nan_only.add(vec3(0.0f), vec3(kInf, 0.0f, 0.0f), vec3(2.0f));
  tree.build(nan_only.view());
  EXPECT_TRUE(tree.empty());
  EXPECT_EQ(tree.stats().skipped_triangles, 2u);
  EXPECT_FALSE(tree.intersect(r, hit));

  // One triangle; the same triangle many times over (no split helps: depth-limited or a leaf);
  // points only (a box of zero area).
  Mesh one{"one", {}, {}};
  one.add(vec3(-1, -1, 2), vec3(1, -1, 2), vec3(0, 1, 2));
  tree.build(one.view());
  r = PreparedRay::make(vec3(0.0f), vec3(0, 0, 1), 0.0f, kInf);
  EXPECT_TRUE(tree.intersect(r, hit));
  EXPECT_EQ(hit.prim, 0u);

  Mesh same{"same", {}, {}};
  for (int i = 0; i < 500; ++i) same.add(vec3(-1, -1, 2), vec3(1, -1, 2), vec3(0, 1, 2));
  tree.build(same.view());
  r = PreparedRay::make(vec3(0.0f), vec3(0, 0, 1), 0.0f, kInf);
  hit = {};
  EXPECT_TRUE(tree.intersect(r, hit));
  EXPECT_EQ(hit.t, 2.0f);

  Mesh points{"points", {}, {}};
  for (int i = 0; i < 50; ++i) points.add(vec3(1.0f), vec3(1.0f), vec3(1.0f));
  tree.build(points.view());
  EXPECT_FALSE(tree.empty());
  r = PreparedRay::make(vec3(0.0f), vec3(1.0f), 0.0f, kInf);
  hit = {};
  EXPECT_FALSE(tree.intersect(r, hit));
}

TEST(KdTree, OptionsAndStats) {
  const Mesh mesh = uv_sphere(32, 64, 1.0f, vec3(0.0f));
  KdTree perfect, loose;
  perfect.build(mesh.view());
  KdBuildOptions options;
  options.perfect_splits = false;
  options.max_depth = 12;
  loose.build(mesh.view(), options);
  EXPECT_LE(loose.stats().max_depth, 12u);
  EXPECT_GT(perfect.stats().leaves, 1u);
  EXPECT_GT(perfect.stats().sah_cost, 0.0f);
  // Clipping can only tighten the events, so the tree's cost does not get worse.
  EXPECT_LE(perfect.stats().sah_cost, loose.stats().sah_cost * 1.05f);
  const auto rays = make_rays(perfect.bounds(), 4000, 8);
  for (const PreparedRay& ray : rays) {
    PreparedRay a = ray, b = ray;
    TriangleHit ha, hb;
    perfect.intersect(a, ha);
    loose.intersect(b, hb);
    ASSERT_TRUE(same_hit(hb, ha));
  }
}
