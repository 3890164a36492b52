// The BVH for dynamic objects (engine/accel/bvh): every query against brute force, the structure's
// invariants, refit, selective restructuring, lazy expansion (also from several threads), packets
// and the generic traversal over boxes; and its 4-wide collapse for single rays (WideBvh).
#include "specula/accel/bvh/bvh.h"
#include "specula/accel/bvh/wide_bvh.h"

#include "accel_test_meshes.h"
#include "packet_occlusion_check.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <set>
#include <thread>
#include <vector>

using namespace specula;
using namespace specula::accel;

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

using test::kBruteForceDivisor;
using test::Mesh;
using test::random_soup;

/// A UV sphere with the zero-area triangles at its poles kept.
Mesh uv_sphere(int rings, int segments, float radius, vec3 centre) {
  return test::uv_sphere(rings, segments, radius, centre, /*pole_slivers=*/true);
}

/// nx × ny quads covering [-2, 2]^2 in the plane z = 0.
Mesh flat_grid(int nx, int ny) { return test::flat_grid(nx, ny, -2.0f, 2.0f); }

/// A soup with degenerate triangles mixed in (points, repeated vertices, segments, collinear
/// vertices, needles, slivers, NaN and infinite vertices), duplicates, and many triangles sharing
/// one centroid.
Mesh degenerate_mix(std::uint32_t seed) {
  Mesh m = random_soup(1200, seed, 1.5f, 0.3f);
  m.name = "degenerate";
  test::add_degenerate_triangles(m, 2000, seed + 1, 1.5f, 3.0f);
  for (int i = 0; i < 300; ++i) m.add(vec3(-0.2f, 0, 0), vec3(0.2f, 0, 0), vec3(0, 0.3f, 0.01f * float(i % 3)));
  for (int i = 0; i < 100; ++i) m.triangles.push_back(m.triangles[std::size_t(i)]); // duplicates
  return m;
}

/// Rays from a pinhole towards the mesh (coherent) and between random points (incoherent), with
/// axis-parallel directions and rays starting inside mixed in.
std::vector<Ray> make_rays(const Aabb& box, int count, std::uint32_t seed, bool coherent) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u01(0.0f, 1.0f);
  const vec3 c = box.center();
  const float radius = glm::length(box.extent()) * 0.5f + 1e-3f;
  std::vector<Ray> rays;
  rays.reserve(std::size_t(count));
  const vec3 eye = c + vec3(0.3f, 0.5f, 2.5f) * radius;
  const int side = int(std::sqrt(float(count))) + 1;
  for (int i = 0; i < count; ++i) {
    Ray r;
    if (coherent) {
      const float x = (float(i % side) + 0.5f) / float(side) * 2.0f - 1.0f;
      const float y = (float(i / side) + 0.5f) / float(side) * 2.0f - 1.0f;
      r.origin = eye;
      r.direction = glm::normalize(c - eye + radius * vec3(x, y, 0.3f * x * y));
    } else {
      auto point = [&] {
        return box.min - 0.2f * box.extent() + 1.4f * box.extent() * vec3(u01(rng), u01(rng), u01(rng));
      };
      r.origin = point();
      r.direction = point() - r.origin;
      if (i % 16 == 0) r.direction = vec3(0.0f, 0.0f, u01(rng) < 0.5f ? -1.0f : 1.0f);
      if (i % 16 == 1) r.direction = vec3(u01(rng) < 0.5f ? -1.0f : 1.0f, 0.0f, 0.0f);
      if (i % 16 == 2) r.direction = vec3(0.0f, u01(rng) - 0.5f, 1.0f);
      if (i % 8 == 3) r.tfar = u01(rng) * radius;
      if (i % 8 == 4) r.tnear = u01(rng) * 0.5f * radius;
    }
    rays.push_back(r);
  }
  return rays;
}

bool same_hit(const TriangleHit& a, const TriangleHit& b) {
  if (a.hit() != b.hit()) return false;
  if (!a.hit()) return true;
  if (a.prim == b.prim) return a.t == b.t;
  return std::abs(a.t - b.t) <= 1e-5f * std::max(1.0f, std::abs(b.t));
}

template <TriangleTest Test, class Tree>
int mismatches_against_brute_force(const Tree& bvh, const TriangleView& view,
                                   const std::vector<Ray>& rays) {
  int bad = 0;
  for (const Ray& ray : rays) {
    const TriangleHit ref = brute_force_closest<Test>(view, PreparedRay::make(ray));
    PreparedRay r = PreparedRay::make(ray);
    TriangleHit hit;
    const bool found = bvh.intersect(r, hit, Test);
    bool ok = found == ref.hit() && same_hit(hit, ref) && (!found || r.tfar == hit.t);
    // The same triangle: the same barycentrics, to the bit (the same operations in the same order).
    ok = ok && (!found || hit.prim != ref.prim || (hit.u == ref.u && hit.v == ref.v));
    ok = ok && bvh.occluded(PreparedRay::make(ray), Test) == ref.hit();
    if (!ok && ++bad <= 3)
      ADD_FAILURE() << "ray o=(" << ray.origin.x << "," << ray.origin.y << "," << ray.origin.z
                    << ") d=(" << ray.direction.x << "," << ray.direction.y << "," << ray.direction.z
                    << ") bvh prim " << hit.prim << " t " << hit.t << ", brute force prim " << ref.prim
                    << " t " << ref.t;
  }
  return bad;
}

template <class Tree>
int mismatches(const Tree& bvh, const TriangleView& view, const std::vector<Ray>& rays) {
  return mismatches_against_brute_force<TriangleTest::watertight>(bvh, view, rays) +
         mismatches_against_brute_force<TriangleTest::moller_trumbore>(bvh, view, rays);
}

Aabb mesh_bounds(const Mesh& m) { return m.bounds(); }

bool contains(const gpu::BvhNode& outer, const gpu::BvhNode& inner) {
  if (inner.bounds_min.x > inner.bounds_max.x) return true; // empty
  return glm::all(glm::lessThanEqual(outer.bounds_min, inner.bounds_min)) &&
         glm::all(glm::greaterThanEqual(outer.bounds_max, inner.bounds_max));
}

/// Walks the reachable tree: each primitive exactly once, children inside parents, leaves within
/// max_leaf, each box the exact union of its children (or its triangles' boxes when `tris`).
void check_structure(const Bvh& bvh, std::uint32_t prim_count, std::uint32_t max_leaf,
                     const TriangleView* tris = nullptr) {
  const auto nodes = bvh.nodes();
  const auto indices = bvh.indices();
  ASSERT_EQ(indices.size(), prim_count);
  std::vector<int> seen(prim_count, 0);
  std::vector<std::uint32_t> stack{0};
  std::uint32_t reached = 0, leaves = 0;
  while (!stack.empty()) {
    const std::uint32_t i = stack.back();
    stack.pop_back();
    ASSERT_LT(i, nodes.size());
    ++reached;
    const gpu::BvhNode& n = nodes[i];
    if (n.count == 0) {
      for (std::uint32_t k = 0; k < 2; ++k) {
        ASSERT_GT(n.index + k, i) << "children follow their parent";
        EXPECT_TRUE(contains(n, nodes[n.index + k]));
        stack.push_back(n.index + k);
      }
      const gpu::BvhNode& a = nodes[n.index];
      const gpu::BvhNode& b = nodes[n.index + 1];
      EXPECT_EQ(n.bounds_min, glm::min(a.bounds_min, b.bounds_min));
      EXPECT_EQ(n.bounds_max, glm::max(a.bounds_max, b.bounds_max));
      continue;
    }
    const std::uint32_t count = n.count & ~gpu::kBvhUnbuilt;
    if (!(n.count & gpu::kBvhUnbuilt)) {
      EXPECT_LE(count, max_leaf);
      ++leaves;
    }
    Aabb box;
    for (std::uint32_t e = n.index; e < n.index + count; ++e) {
      ASSERT_LT(indices[e], prim_count);
      ++seen[indices[e]];
      if (tris) {
        bool finite = true;
        for (int k = 0; k < 3; ++k) finite = finite && is_finite(tris->vertex(indices[e], k));
        if (finite) box.grow(tris->bounds(indices[e]));
      }
    }
    if (tris) {
      EXPECT_EQ(n.bounds_min, box.min);
      EXPECT_EQ(n.bounds_max, box.max);
    }
  }
  for (std::uint32_t p = 0; p < prim_count; ++p) ASSERT_EQ(seen[p], 1) << "primitive " << p;
  EXPECT_EQ(bvh.stats().nodes, reached);
  EXPECT_EQ(bvh.stats().leaves, leaves);
}

/// The leaves of a tree as (bounds, sorted primitives), in traversal order: two trees with the same
/// topology and boxes give the same list whatever their layout.
struct LeafSig {
  vec3 lo, hi;
  std::vector<std::uint32_t> prims;
  bool operator==(const LeafSig&) const = default;
};
std::vector<LeafSig> leaf_signature(const Bvh& bvh) {
  std::vector<LeafSig> out;
  const auto nodes = bvh.nodes();
  if (nodes.empty()) return out;
  std::vector<std::uint32_t> stack{0};
  while (!stack.empty()) {
    const gpu::BvhNode& n = nodes[stack.back()];
    stack.pop_back();
    if (n.count == 0) {
      stack.push_back(n.index + 1);
      stack.push_back(n.index);
      continue;
    }
    LeafSig s{n.bounds_min, n.bounds_max, {}};
    for (std::uint32_t e = n.index; e < n.index + (n.count & ~gpu::kBvhUnbuilt); ++e)
      s.prims.push_back(bvh.indices()[e]);
    std::sort(s.prims.begin(), s.prims.end());
    out.push_back(std::move(s));
  }
  return out;
}

/// Each named (sphere, soup, grid, degenerate) for the failure messages.
std::vector<Mesh> test_meshes() {
  return {uv_sphere(32, 48, 1.0f, vec3(0.2f, -0.1f, 0.3f)), random_soup(3000, 7, 2.0f, 0.25f),
          flat_grid(40, 30), degenerate_mix(11)};
}

} // namespace

TEST(Bvh, EmptyInputGivesAnEmptyTree) {
  Bvh bvh;
  EXPECT_TRUE(bvh.empty());
  bvh.build(TriangleView{});
  EXPECT_TRUE(bvh.empty());
  EXPECT_TRUE(bvh.nodes().empty());
  PreparedRay r = PreparedRay::make(vec3(0), vec3(0, 0, 1), 0.0f, kInf);
  TriangleHit hit;
  EXPECT_FALSE(bvh.intersect(r, hit));
  EXPECT_FALSE(bvh.occluded(r));
  int calls = 0;
  bvh.traverse(r, [&](std::uint32_t, PreparedRay&) { return ++calls, false; });
  EXPECT_EQ(calls, 0);
  bvh.build(std::span<const Aabb>{}, {.lazy = true});
  EXPECT_TRUE(bvh.empty());
  bvh.expand_all();
  RayPacket<4> p{};
  PacketHits<4> h;
  h.clear();
  const bool active[4] = {true, true, true, true};
  bvh.intersect4(p, h, active);
  EXPECT_EQ(h.prim[0], 0xFFFFFFFFu);
}

TEST(Bvh, ClosestAndAnyHitEqualBruteForce) {
  int total_rays = 0;
  for (const Mesh& mesh : test_meshes()) {
    SCOPED_TRACE(mesh.name);
    const TriangleView view = mesh.view();
    Bvh bvh;
    bvh.build(view);
    check_structure(bvh, view.count, 4, &view);
    const Aabb box = mesh_bounds(mesh);
    for (bool coherent : {true, false}) {
      const auto rays =
          make_rays(box, 13000 / kBruteForceDivisor, 100 + (coherent ? 1u : 0u), coherent);
      EXPECT_EQ(mismatches(bvh, view, rays), 0) << (coherent ? "coherent" : "incoherent");
      total_rays += int(rays.size());
    }
  }
  EXPECT_GE(total_rays, 100000 / kBruteForceDivisor);
}

TEST(Bvh, OptionsAreHonoured) {
  const Mesh m = random_soup(2000, 3, 2.0f, 0.2f);
  const TriangleView view = m.view();
  const auto rays = make_rays(mesh_bounds(m), 3000 / kBruteForceDivisor, 5, false);
  for (std::uint32_t max_leaf : {1u, 2u, 8u})
    for (std::uint32_t bins : {2u, 8u, 32u, 1000u}) {
      SCOPED_TRACE(testing::Message() << "max_leaf " << max_leaf << " bins " << bins);
      Bvh bvh;
      bvh.build(view, {.bins = bins, .max_leaf = max_leaf, .intersection_cost = 0.5f});
      check_structure(bvh, view.count, max_leaf, &view);
      EXPECT_EQ(mismatches(bvh, view, rays), 0);
      EXPECT_GT(bvh.stats().sah_cost, 0.0f);
      EXPECT_FLOAT_EQ(bvh.stats().sah_cost, bvh.sah_cost());
    }
}

TEST(Bvh, BuildIsDeterministicWhateverTheThreadCount) {
  const Mesh m = random_soup(30000, 21, 4.0f, 0.1f); // large enough for parallel subtrees
  Bvh many, one;
  many.build(m.view());
  {
    tbb::global_control single(tbb::global_control::max_allowed_parallelism, 1);
    one.build(m.view());
  }
  ASSERT_EQ(many.nodes().size(), one.nodes().size());
  EXPECT_EQ(0, std::memcmp(many.nodes().data(), one.nodes().data(), many.nodes().size_bytes()));
  EXPECT_TRUE(std::equal(many.indices().begin(), many.indices().end(), one.indices().begin()));
  check_structure(many, m.view().count, 4, nullptr);
}

TEST(Bvh, InvalidRaysMissWithoutTraversal) {
  const Mesh m = uv_sphere(8, 12, 1.0f, vec3(0));
  Bvh bvh;
  bvh.build(m.view());
  const Ray bad[] = {{vec3(kNaN, 0, 3), 0.0f, vec3(0, 0, -1), kInf},
                     {vec3(0, 0, 3), 0.0f, vec3(0, 0, 0), kInf},
                     {vec3(0, 0, 3), 0.0f, vec3(0, kInf, -1), kInf},
                     {vec3(0, 0, 3), 2.0f, vec3(0, 0, -1), 1.0f},
                     {vec3(0, 0, 3), -1.0f, vec3(0, 0, -1), kInf}};
  for (const Ray& ray : bad) {
    PreparedRay r = PreparedRay::make(ray);
    TriangleHit hit;
    EXPECT_FALSE(bvh.intersect(r, hit));
    EXPECT_FALSE(bvh.occluded(r));
    int calls = 0;
    bvh.traverse(r, [&](std::uint32_t, PreparedRay&) { return ++calls, false; });
    EXPECT_EQ(calls, 0);
  }
}

TEST(Bvh, NanVerticesAndBoxesDoNotBreakTheBuild) {
  Mesh m = random_soup(2000, 9, 2.0f, 0.3f);
  for (std::size_t i = 0; i < m.positions.size(); i += 37) m.positions[i].y = kNaN;
  for (std::size_t i = 5; i < m.positions.size(); i += 101) m.positions[i].x = kInf;
  const TriangleView view = m.view();
  for (bool lazy : {false, true}) {
    Bvh bvh;
    bvh.build(view, {.lazy = lazy});
    bvh.expand_all();
    check_structure(bvh, view.count, 4, &view);
    EXPECT_EQ(mismatches(bvh, view, make_rays(mesh_bounds(m), 3000, 17, false)), 0);
  }
  // All NaN: a tree that nothing enters.
  std::vector<Aabb> boxes(50, Aabb{vec3(kNaN), vec3(kNaN)});
  boxes[7] = Aabb{vec3(0), vec3(1)};
  Bvh bvh;
  bvh.build(boxes);
  EXPECT_EQ(bvh.indices().size(), boxes.size());
  PreparedRay r = PreparedRay::make(vec3(0.5f, 0.5f, -1), vec3(0, 0, 1), 0.0f, kInf);
  std::vector<std::uint32_t> visited;
  bvh.traverse(r, [&](std::uint32_t prim, PreparedRay&) { return visited.push_back(prim), false; });
  EXPECT_TRUE(std::find(visited.begin(), visited.end(), 7u) != visited.end());
}

TEST(Bvh, PacketsEqualSingleRaysPerLane) {
  const Mesh m = random_soup(4000, 31, 2.0f, 0.3f);
  const TriangleView view = m.view();
  Bvh bvh;
  bvh.build(view);
  const auto coherent = make_rays(mesh_bounds(m), 4096, 41, true);
  const auto incoherent = make_rays(mesh_bounds(m), 4096, 43, false);
  std::mt19937 rng(47);
  for (TriangleTest test : {TriangleTest::watertight, TriangleTest::moller_trumbore})
    for (const auto* rays : {&coherent, &incoherent}) {
      int bad = 0;
      auto run = [&]<int N>(std::integral_constant<int, N>) {
        for (std::size_t base = 0; base + N <= rays->size(); base += N) {
          RayPacket<N> p;
          PacketHits<N> h;
          h.clear();
          bool active[N];
          for (int i = 0; i < N; ++i) {
            Ray ray = (*rays)[base + std::size_t(i)];
            if (rng() % 9 == 0) ray.direction = -ray.direction; // mixed signs in a packet
            if (rng() % 13 == 0) ray.direction = vec3(0); // invalid lane
            p.ox[i] = ray.origin.x, p.oy[i] = ray.origin.y, p.oz[i] = ray.origin.z;
            p.dx[i] = ray.direction.x, p.dy[i] = ray.direction.y, p.dz[i] = ray.direction.z;
            p.tnear[i] = ray.tnear, p.tfar[i] = ray.tfar;
            active[i] = rng() % 7 != 0;
          }
          const RayPacket<N> before = p;
          if constexpr (N == 4) bvh.intersect4(p, h, active, test);
          else bvh.intersect8(p, h, active, test);
          for (int i = 0; i < N; ++i) {
            PreparedRay r = PreparedRay::make(vec3(before.ox[i], before.oy[i], before.oz[i]),
                                              vec3(before.dx[i], before.dy[i], before.dz[i]),
                                              before.tnear[i], before.tfar[i]);
            TriangleHit single;
            if (active[i]) bvh.intersect(r, single, test);
            const TriangleHit packet{h.t[i], h.u[i], h.v[i], h.prim[i]};
            const bool ok = same_hit(packet, single) && p.tfar[i] == r.tfar;
            if (!ok && ++bad <= 3)
              ADD_FAILURE() << "N=" << N << " lane " << i << " packet prim " << packet.prim << " t "
                            << packet.t << ", single prim " << single.prim << " t " << single.t;
          }
        }
      };
      run(std::integral_constant<int, 4>{});
      run(std::integral_constant<int, 8>{});
      EXPECT_EQ(bad, 0);
    }
}

TEST(Bvh, RefitAfterDeformationStaysExact) {
  Mesh m = uv_sphere(40, 60, 1.0f, vec3(0));
  const std::vector<vec3> rest = m.positions;
  Bvh bvh;
  bvh.build(m.view());
  // A wave.
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    const vec3 p = rest[i];
    m.positions[i] = p + vec3(0.0f, 0.3f * std::sin(4.0f * p.x + 2.0f * p.z), 0.0f);
  }
  bvh.refit(m.view());
  {
    const TriangleView view = m.view();
    check_structure(bvh, view.count, 4, &view);
    EXPECT_EQ(mismatches(bvh, view, make_rays(mesh_bounds(m), 6000 / kBruteForceDivisor, 51, false)), 0);
    EXPECT_EQ(mismatches(bvh, view, make_rays(mesh_bounds(m), 6000 / kBruteForceDivisor, 52, true)), 0);
  }
  // A large random displacement, into a new vertex array.
  std::mt19937 rng(53);
  std::uniform_real_distribution<float> d(-1.5f, 1.5f);
  Mesh moved = m;
  for (vec3& p : moved.positions) p += vec3(d(rng), d(rng), d(rng));
  bvh.refit(moved.view());
  const TriangleView view = moved.view();
  check_structure(bvh, view.count, 4, &view);
  EXPECT_EQ(mismatches(bvh, view, make_rays(mesh_bounds(moved), 6000 / kBruteForceDivisor, 54, false)), 0);
  EXPECT_GT(bvh.sah_cost(), bvh.stats().sah_cost); // it degraded
}

TEST(Bvh, RestructureRebuildsOnlyDegradedSubtrees) {
  Mesh m = flat_grid(80, 80);
  Bvh bvh;
  bvh.build(m.view());
  const float built = bvh.sah_cost();

  // No degradation (the same mesh, then a rigid translation): nothing rebuilt.
  bvh.refit(m.view());
  RestructureStats rs = bvh.restructure(m.view(), 1.3f);
  EXPECT_EQ(rs.subtrees_rebuilt, 0u);
  EXPECT_GT(rs.nodes_visited, 0u);
  for (vec3& p : m.positions) p += vec3(3.0f, -1.0f, 0.5f);
  bvh.refit(m.view());
  rs = bvh.restructure(m.view(), 1.3f);
  EXPECT_EQ(rs.subtrees_rebuilt, 0u);
  EXPECT_EQ(rs.primitives_rebuilt, 0u);
  EXPECT_NEAR(bvh.sah_cost(), built, 1e-3f * built);

  // A local, heavy deformation: scramble the vertices in one corner of the grid.
  std::mt19937 rng(61);
  std::uniform_real_distribution<float> d(-0.3f, 0.3f);
  std::vector<bool> deformed_vertex(m.positions.size(), false);
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    const vec3 p = m.positions[i] - vec3(3.0f, -1.0f, 0.5f);
    if (p.x < -1.4f && p.y < -1.4f) {
      m.positions[i] += vec3(d(rng), d(rng), 0.0f); // in the plane: the root box stays
      deformed_vertex[i] = true;
    }
  }
  std::vector<bool> deformed(m.triangles.size(), false);
  for (std::size_t t = 0; t < m.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) deformed[t] = deformed[t] || deformed_vertex[m.triangles[t][k]];
  bvh.refit(m.view());
  const std::vector<gpu::BvhNode> old_nodes(bvh.nodes().begin(), bvh.nodes().end());
  const std::vector<std::uint32_t> old_indices(bvh.indices().begin(), bvh.indices().end());
  rs = bvh.restructure(m.view(), 1.3f);
  EXPECT_GE(rs.subtrees_rebuilt, 1u);
  // Some triangles were rebuilt, not all: the root kept its place (the stats' rebuilt count).
  EXPECT_GT(rs.primitives_rebuilt, 0u);
  EXPECT_LT(rs.primitives_rebuilt, m.triangles.size());
  EXPECT_LT(rs.sah_after, rs.sah_before);
  EXPECT_FLOAT_EQ(rs.sah_after, bvh.sah_cost());
  const TriangleView view = m.view();
  check_structure(bvh, view.count, 4, &view);
  EXPECT_EQ(mismatches(bvh, view, make_rays(mesh_bounds(m), 8000 / kBruteForceDivisor, 62, false)), 0);
  EXPECT_EQ(mismatches(bvh, view, make_rays(mesh_bounds(m), 8000 / kBruteForceDivisor, 63, true)), 0);

  // Old and new trees side by side: where they differ is a rebuilt subtree, and every rebuilt
  // subtree holds deformed triangles; the root was not rebuilt.
  const auto nodes = bvh.nodes();
  auto prims_of = [](std::span<const gpu::BvhNode> ns, std::span<const std::uint32_t> idx, std::uint32_t root) {
    std::vector<std::uint32_t> out, stack{root};
    while (!stack.empty()) {
      const gpu::BvhNode& n = ns[stack.back()];
      stack.pop_back();
      if (n.count == 0) stack.insert(stack.end(), {n.index, n.index + 1});
      else
        for (std::uint32_t e = n.index; e < n.index + n.count; ++e) out.push_back(idx[e]);
    }
    std::sort(out.begin(), out.end());
    return out;
  };
  std::uint32_t differing = 0;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> stack{{0u, 0u}};
  bool root_differs = false;
  while (!stack.empty()) {
    const auto [o, n] = stack.back();
    stack.pop_back();
    const gpu::BvhNode& a = old_nodes[o];
    const gpu::BvhNode& b = nodes[n];
    ASSERT_EQ(a.bounds_min, b.bounds_min);
    ASSERT_EQ(a.bounds_max, b.bounds_max);
    bool same = (a.count == 0) == (b.count == 0);
    if (same && a.count == 0) {
      for (std::uint32_t k = 0; k < 2; ++k)
        same = same && old_nodes[a.index + k].bounds_min == nodes[b.index + k].bounds_min &&
               old_nodes[a.index + k].bounds_max == nodes[b.index + k].bounds_max;
    } else if (same) {
      same = prims_of(old_nodes, old_indices, o) == prims_of(nodes, bvh.indices(), n);
    }
    if (!same) {
      ++differing;
      root_differs = root_differs || o == 0;
      const auto prims = prims_of(nodes, bvh.indices(), n);
      EXPECT_TRUE(std::any_of(prims.begin(), prims.end(), [&](std::uint32_t p) { return deformed[p]; }));
      continue;
    }
    if (a.count == 0) {
      stack.push_back({a.index, b.index});
      stack.push_back({a.index + 1, b.index + 1});
    }
  }
  EXPECT_GE(differing, 1u);
  EXPECT_LE(differing, rs.subtrees_rebuilt);
  EXPECT_FALSE(root_differs);

  // A second restructure right after finds nothing to do.
  bvh.refit(m.view());
  EXPECT_EQ(bvh.restructure(m.view(), 1.3f).subtrees_rebuilt, 0u);
}

TEST(Bvh, RestructureAfterGlobalScramble) {
  Mesh m = uv_sphere(30, 40, 1.0f, vec3(0));
  Bvh bvh;
  bvh.build(m.view());
  std::mt19937 rng(71);
  std::shuffle(m.positions.begin(), m.positions.end(), rng); // every triangle is now a sliver across
  bvh.refit(m.view());
  const RestructureStats rs = bvh.restructure(m.view(), 1.3f);
  EXPECT_GE(rs.subtrees_rebuilt, 1u);
  EXPECT_LT(rs.sah_after, rs.sah_before);
  const TriangleView view = m.view();
  check_structure(bvh, view.count, 4, &view);
  EXPECT_EQ(mismatches(bvh, view, make_rays(mesh_bounds(m), 6000 / kBruteForceDivisor, 72, false)), 0);
  // Refit still works on the restructured layout.
  for (vec3& p : m.positions) p *= 1.5f;
  bvh.refit(m.view());
  check_structure(bvh, view.count, 4, &view);
  EXPECT_EQ(mismatches(bvh, view, make_rays(mesh_bounds(m), 3000 / kBruteForceDivisor, 73, false)), 0);
}

TEST(Bvh, LazyTreeEqualsEagerTree) {
  const Mesh m = random_soup(20000, 81, 3.0f, 0.15f);
  const TriangleView view = m.view();
  Bvh eager, lazy;
  eager.build(view);
  lazy.build(view, {.lazy = true, .lazy_depth = 3});
  EXPECT_LT(lazy.stats().nodes, eager.stats().nodes);
  bool any_unbuilt = false;
  for (const gpu::BvhNode& n : lazy.nodes()) any_unbuilt = any_unbuilt || (n.count & gpu::kBvhUnbuilt);
  EXPECT_TRUE(any_unbuilt);
  const auto rays = make_rays(mesh_bounds(m), 2000, 82, true); // a narrow view: not every subtree
  for (const Ray& ray : rays) {
    PreparedRay a = PreparedRay::make(ray), b = a;
    TriangleHit ha, hb;
    eager.intersect(a, ha);
    lazy.intersect(b, hb);
    ASSERT_TRUE(same_hit(ha, hb));
  }
  const std::uint32_t expansions = lazy.stats().lazy_expansions;
  EXPECT_GT(expansions, 0u);
  lazy.expand_all();
  EXPECT_GT(lazy.stats().lazy_expansions, expansions);
  for (const gpu::BvhNode& n : lazy.nodes()) EXPECT_EQ(n.count & gpu::kBvhUnbuilt, 0u);
  check_structure(lazy, view.count, 4, &view);
  EXPECT_EQ(lazy.stats().nodes, eager.stats().nodes);
  EXPECT_EQ(leaf_signature(lazy), leaf_signature(eager)); // the same tree, laid out differently
  EXPECT_FLOAT_EQ(lazy.sah_cost(), eager.sah_cost());
}

TEST(Bvh, LazyExpansionFromSeveralThreads) {
  const Mesh m = random_soup(30000, 91, 3.0f, 0.15f);
  const TriangleView view = m.view();
  Bvh eager;
  eager.build(view);
  const auto rays = make_rays(mesh_bounds(m), 24000, 92, false);
  std::vector<TriangleHit> expected(rays.size());
  for (std::size_t i = 0; i < rays.size(); ++i) {
    PreparedRay r = PreparedRay::make(rays[i]);
    eager.intersect(r, expected[i]);
  }
  for (int round = 0; round < 3; ++round) {
    Bvh lazy;
    lazy.build(view, {.lazy = true, .lazy_depth = 2});
    constexpr int kThreads = 4;
    std::vector<int> bad(kThreads, 0);
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t)
      threads.emplace_back([&, t] {
        // Every thread walks all rays from a different start: the same subtrees at the same time.
        for (std::size_t k = 0; k < rays.size(); ++k) {
          const std::size_t i = (k + std::size_t(t) * rays.size() / kThreads) % rays.size();
          PreparedRay r = PreparedRay::make(rays[i]);
          TriangleHit hit;
          lazy.intersect(r, hit);
          if (!same_hit(hit, expected[i])) ++bad[std::size_t(t)];
          if (k % 7 == 0) {
            RayPacket<8> p;
            PacketHits<8> h;
            h.clear();
            bool active[8];
            for (int j = 0; j < 8; ++j) {
              const Ray& q = rays[(i + std::size_t(j)) % rays.size()];
              p.ox[j] = q.origin.x, p.oy[j] = q.origin.y, p.oz[j] = q.origin.z;
              p.dx[j] = q.direction.x, p.dy[j] = q.direction.y, p.dz[j] = q.direction.z;
              p.tnear[j] = q.tnear, p.tfar[j] = q.tfar;
              active[j] = true;
            }
            lazy.intersect8(p, h, active);
            for (int j = 0; j < 8; ++j)
              if (!same_hit({h.t[j], h.u[j], h.v[j], h.prim[j]}, expected[(i + std::size_t(j)) % rays.size()]))
                ++bad[std::size_t(t)];
          }
        }
      });
    for (auto& th : threads) th.join();
    for (int t = 0; t < kThreads; ++t) EXPECT_EQ(bad[std::size_t(t)], 0) << "thread " << t;
    EXPECT_GT(lazy.stats().lazy_expansions, 0u);
    lazy.expand_all();
    check_structure(lazy, view.count, 4, &view);
    EXPECT_EQ(leaf_signature(lazy), leaf_signature(eager));
  }
}

TEST(Bvh, LazyTreeRefitsAndRestructures) {
  Mesh m = uv_sphere(40, 50, 1.0f, vec3(0));
  Bvh bvh;
  bvh.build(m.view(), {.lazy = true, .lazy_depth = 4});
  std::mt19937 rng(95);
  std::uniform_real_distribution<float> d(-0.8f, 0.8f);
  for (vec3& p : m.positions) p += vec3(d(rng), d(rng), d(rng));
  bvh.refit(m.view());
  const TriangleView view = m.view();
  check_structure(bvh, view.count, 4, &view);
  bvh.restructure(m.view(), 1.2f);
  check_structure(bvh, view.count, 4, &view);
  EXPECT_EQ(mismatches(bvh, view, make_rays(mesh_bounds(m), 5000, 96, false)), 0);
  bvh.expand_all();
  check_structure(bvh, view.count, 4, &view);
}

TEST(Bvh, BoxTraversalVisitsExactlyTheOverlappedBoxes) {
  std::mt19937 rng(101);
  std::uniform_real_distribution<float> pos(-5.0f, 5.0f), size(0.05f, 0.8f);
  std::vector<Aabb> boxes(3000);
  for (Aabb& b : boxes) {
    const vec3 c(pos(rng), pos(rng), pos(rng));
    const vec3 h(size(rng), size(rng), size(rng));
    b = {c - h, c + h};
  }
  Aabb all;
  for (const Aabb& b : boxes) all.grow(b);
  for (bool lazy : {false, true}) {
    Bvh bvh;
    bvh.build(boxes, {.max_leaf = 1, .lazy = lazy, .lazy_depth = 3});
    check_structure(bvh, std::uint32_t(boxes.size()), 1);
    int bad = 0;
    for (const Ray& ray : make_rays(all, 3000, 102, false)) {
      PreparedRay r = PreparedRay::make(ray);
      std::vector<std::uint32_t> visited;
      bvh.traverse(r, [&](std::uint32_t prim, PreparedRay&) { return visited.push_back(prim), false; });
      std::vector<std::uint32_t> expected;
      if (r.valid())
        for (std::uint32_t i = 0; i < boxes.size(); ++i) {
          float t0, t1;
          if (intersect_box(r, boxes[i].min, boxes[i].max, t0, t1)) expected.push_back(i);
        }
      std::sort(visited.begin(), visited.end());
      if (visited != expected) ++bad;
    }
    EXPECT_EQ(bad, 0) << (lazy ? "lazy" : "eager");
  }
  // With bigger leaves every overlapped box is still visited, each once.
  Bvh bvh;
  bvh.build(boxes, {.max_leaf = 4});
  for (const Ray& ray : make_rays(all, 500, 103, false)) {
    PreparedRay r = PreparedRay::make(ray);
    std::vector<std::uint32_t> visited;
    bvh.traverse(r, [&](std::uint32_t prim, PreparedRay&) { return visited.push_back(prim), false; });
    std::sort(visited.begin(), visited.end());
    EXPECT_TRUE(std::adjacent_find(visited.begin(), visited.end()) == visited.end());
    for (std::uint32_t i = 0; i < boxes.size(); ++i) {
      float t0, t1;
      if (intersect_box(r, boxes[i].min, boxes[i].max, t0, t1)) {
        EXPECT_TRUE(std::binary_search(visited.begin(), visited.end(), i));
      }
    }
  }
}

TEST(Bvh, BoxTraversalIsFrontToBackAndStops) {
  std::vector<Aabb> boxes;
  for (int i = 0; i < 200; ++i) boxes.push_back({vec3(float(i), -0.4f, -0.4f), vec3(float(i) + 0.5f, 0.4f, 0.4f)});
  std::mt19937 rng(111);
  std::shuffle(boxes.begin(), boxes.end(), rng);
  Bvh bvh;
  bvh.build(boxes, {.max_leaf = 1});
  for (float dir : {1.0f, -1.0f}) {
    PreparedRay r = PreparedRay::make(vec3(dir > 0 ? -1.0f : 201.0f, 0.01f, 0.02f), vec3(dir, 0.001f, 0), 0.0f, kInf);
    std::vector<float> xs;
    bvh.traverse(r, [&](std::uint32_t prim, PreparedRay&) { return xs.push_back(boxes[prim].min.x), false; });
    ASSERT_EQ(xs.size(), boxes.size());
    for (std::size_t i = 1; i < xs.size(); ++i) EXPECT_EQ(xs[i] > xs[i - 1], dir > 0);
    // Stop at the third box; shrink tfar past the tenth: later boxes are not visited.
    int calls = 0;
    bvh.traverse(r, [&](std::uint32_t, PreparedRay&) { return ++calls == 3; });
    EXPECT_EQ(calls, 3);
    PreparedRay s = r;
    calls = 0;
    bvh.traverse(s, [&](std::uint32_t prim, PreparedRay& q) {
      ++calls;
      if (calls == 10) q.tfar = std::abs(boxes[prim].min.x - q.org.x) + 0.1f;
      return false;
    });
    EXPECT_EQ(calls, 10);
  }
}

TEST(Bvh, MovedTreeKeepsWorking) {
  const Mesh m = uv_sphere(16, 24, 1.0f, vec3(0));
  Bvh a;
  a.build(m.view(), {.lazy = true, .lazy_depth = 2});
  Bvh b = std::move(a);
  Bvh c;
  c = std::move(b);
  const TriangleView view = m.view();
  EXPECT_EQ(mismatches(c, view, make_rays(mesh_bounds(m), 2000, 121, false)), 0);
  a.build(m.view()); // a moved-from tree can be built again
  EXPECT_EQ(mismatches(a, view, make_rays(mesh_bounds(m), 500, 122, false)), 0);
}

// ---- The 4-wide collapse (wide_bvh.h) ----------------------------------------------------------

namespace {

/// A binary BVH over `view` and its 4-wide collapse.
struct Trees {
  Bvh binary;
  WideBvh wide;
};
Trees build_trees(const TriangleView& view) {
  Trees t;
  t.binary.build(view);
  t.wide.build(t.binary, view);
  return t;
}

/// Walks the wide tree: every triangle of the binary tree in exactly one group lane, groups full
/// but for a leaf's last, unused lanes NaN; each child box the union of its subtree's triangle
/// boxes (finite triangles), and inside the binary root's box.
void check_wide_structure(const WideBvh& wide, const Bvh& binary, const TriangleView& tris) {
  const auto nodes = wide.nodes();
  const auto groups = wide.groups();
  ASSERT_FALSE(nodes.empty());
  std::vector<int> seen(tris.count, 0);
  std::uint32_t leaves = 0, empty_slots = 0;
  // Returns the box of the subtree's finite triangles.
  const auto walk = [&](auto&& self, std::uint32_t node) -> Aabb {
    Aabb all;
    const WideBvhNode& n = nodes[node];
    for (int i = 0; i < 4; ++i) {
      const vec3 lo(n.lo[0][i], n.lo[1][i], n.lo[2][i]), hi(n.hi[0][i], n.hi[1][i], n.hi[2][i]);
      Aabb box;
      if (n.count[i] == 0 && n.child[i] == 0) { // an unused slot (no node has the root as a child)
        ++empty_slots;
        EXPECT_EQ(lo, vec3(std::numeric_limits<float>::infinity()));
        continue;
      }
      if (n.count[i] == 0) {
        EXPECT_GT(n.child[i], node) << "children follow their parent";
        box = self(self, n.child[i]);
      } else {
        ++leaves;
        for (std::uint32_t g = n.child[i]; g < n.child[i] + n.count[i]; ++g) {
          const WideTriangles& w = groups[g];
          for (int lane = 0; lane < 4; ++lane) {
            const std::uint32_t prim = w.prim[lane];
            if (prim == 0xFFFFFFFFu) {
              EXPECT_EQ(g + 1, n.child[i] + n.count[i]) << "only the last group has unused lanes";
              EXPECT_TRUE(std::isnan(w.p[0][0][lane]));
              continue;
            }
            EXPECT_LT(prim, tris.count);
            if (prim >= tris.count) continue;
            ++seen[prim];
            bool finite = true;
            for (int k = 0; k < 3; ++k) {
              for (int a = 0; a < 3; ++a) // the copy, bit for bit (NaN vertices too)
                EXPECT_EQ(std::bit_cast<std::uint32_t>(w.p[k][a][lane]),
                          std::bit_cast<std::uint32_t>(tris.vertex(prim, k)[a]));
              finite = finite && is_finite(tris.vertex(prim, k));
            }
            if (finite) box.grow(tris.bounds(prim));
          }
        }
      }
      if (!box.empty()) {
        EXPECT_EQ(lo, box.min);
        EXPECT_EQ(hi, box.max);
      }
      all.grow(box);
    }
    return all;
  };
  const Aabb root = walk(walk, 0);
  EXPECT_EQ(root.min, binary.bounds().min);
  EXPECT_EQ(root.max, binary.bounds().max);
  for (std::uint32_t p = 0; p < tris.count; ++p) ASSERT_EQ(seen[p], 1) << "triangle " << p;
  EXPECT_EQ(wide.stats().leaves, leaves);
  EXPECT_EQ(wide.stats().empty_slots, empty_slots);
  EXPECT_EQ(wide.stats().nodes, nodes.size());
  EXPECT_EQ(wide.stats().triangles, tris.count);
}

} // namespace

TEST(WideBvh, EmptyTreeMissesEverything) {
  auto [binary, wide] = build_trees(TriangleView{});
  EXPECT_TRUE(wide.empty());
  PreparedRay r = PreparedRay::make(vec3(0), vec3(0, 0, 1), 0.0f, kInf);
  TriangleHit hit;
  EXPECT_FALSE(wide.intersect(r, hit));
  EXPECT_FALSE(wide.occluded(r));
}

TEST(WideBvh, ClosestAndAnyHitEqualBruteForceToTheBit) {
  int total_rays = 0;
  for (const Mesh& mesh : test_meshes()) {
    SCOPED_TRACE(mesh.name);
    const TriangleView view = mesh.view();
    auto [binary, wide] = build_trees(view);
    check_wide_structure(wide, binary, view);
    // Half as deep or so: a wide node stands for up to three binary ones.
    EXPECT_LT(wide.stats().nodes, binary.stats().nodes / 2);
    const Aabb box = mesh_bounds(mesh);
    for (bool coherent : {true, false}) {
      const auto rays =
          make_rays(box, 13000 / kBruteForceDivisor, 200 + (coherent ? 1u : 0u), coherent);
      EXPECT_EQ(mismatches(wide, view, rays), 0) << (coherent ? "coherent" : "incoherent");
      total_rays += int(rays.size());
    }
  }
  EXPECT_GE(total_rays, 100000 / kBruteForceDivisor);
}

TEST(WideBvh, RaysThroughSharedEdgesAndVerticesDoNotLeak) {
  // A closed sphere: rays from the centre through every vertex and every edge midpoint, and rays
  // from outside aimed at them, must hit (the lane-wise test keeps the scalar test's
  // watertightness, its double-precision fallback included).
  const Mesh m = test::uv_sphere(24, 32, 1.0f, vec3(0.1f, 0.2f, -0.3f), /*pole_slivers=*/false);
  const TriangleView view = m.view();
  auto [binary, wide] = build_trees(view);
  const vec3 c(0.1f, 0.2f, -0.3f);
  int rays = 0, leaks = 0;
  for (std::uint32_t t = 0; t < view.count; ++t) {
    for (int k = 0; k < 3; ++k) {
      const vec3 a = view.vertex(t, k), b = view.vertex(t, (k + 1) % 3);
      for (const vec3& target : {a, 0.5f * (a + b)}) {
        const vec3 out = c + 3.0f * (target - c);
        for (const Ray& ray : {Ray{c, 0.0f, target - c}, Ray{out, 0.0f, target - out}}) {
          PreparedRay r = PreparedRay::make(ray);
          TriangleHit hit;
          ++rays;
          leaks += wide.intersect(r, hit) ? 0 : 1;
          leaks += wide.occluded(PreparedRay::make(ray)) ? 0 : 1;
        }
      }
    }
  }
  EXPECT_GT(rays, 10000);
  EXPECT_EQ(leaks, 0);
}

TEST(WideBvh, LazyBinaryTreeCollapsesToTheEagerOne) {
  const Mesh m = random_soup(5000, 91, 3.0f, 0.15f);
  const TriangleView view = m.view();
  Bvh eager, lazy;
  eager.build(view);
  lazy.build(view, {.lazy = true, .lazy_depth = 2});
  WideBvh a, b;
  a.build(eager, view);
  b.build(lazy, view); // expands the lazy tree first
  check_wide_structure(b, lazy, view);
  EXPECT_EQ(a.stats().nodes, b.stats().nodes);
  EXPECT_EQ(a.stats().leaves, b.stats().leaves);
  EXPECT_EQ(mismatches(b, view, make_rays(mesh_bounds(m), 3000 / kBruteForceDivisor, 92, false)),
            0);
}

TEST(WideBvh, EdgeFunctionsThatRoundToZeroAreRecomputedLaneByLane) {
  // Triangles (a, b, c) in the plane z = 0, seen by the ray from (0, 0, -1) along +z, so that ray
  // space is the xy plane: b and c nearly opposite about the origin, with c × b rounding to exactly
  // 0 in single precision but not in double. a is placed so that the other two edge functions have
  // the same sign s: the ray then hits exactly when the double-precision sign of the first is s as
  // well. In single precision alone every one of them would be a hit on the edge.
  std::mt19937 rng(2026);
  std::uniform_real_distribution<float> u(0.5f, 2.0f);
  int cases = 0, misses = 0;
  for (int attempt = 0; attempt < 200000 && cases < 300; ++attempt) {
    const float bx = u(rng), by = u(rng), k = u(rng);
    const float cx = -bx * k;
    float cy = -by * k;
    cy = std::nextafter(cy, attempt % 2 == 0 ? 0.0f : -10.0f);
    const float U = cx * by - cy * bx;
    const double Ud = double(cx) * double(by) - double(cy) * double(bx);
    if (U != 0.0f || Ud == 0.0) continue;
    const float s = attempt % 4 < 2 ? 1.0f : -1.0f;
    test::Mesh m;
    m.add(vec3(-by * s, bx * s, 0.0f), vec3(bx, by, 0.0f), vec3(cx, cy, 0.0f));
    const TriangleView view = m.view();
    auto [binary, wide] = build_trees(view);
    const Ray ray{vec3(0.0f, 0.0f, -1.0f), 0.0f, vec3(0.0f, 0.0f, 1.0f)};
    const TriangleHit ref = brute_force_closest(view, PreparedRay::make(ray));
    PreparedRay r = PreparedRay::make(ray);
    TriangleHit hit;
    EXPECT_EQ(wide.intersect(r, hit), ref.hit()) << "case " << cases;
    EXPECT_TRUE(same_hit(hit, ref));
    EXPECT_EQ(wide.occluded(PreparedRay::make(ray)), ref.hit());
    ++cases;
    misses += ref.hit() ? 0 : 1;
  }
  EXPECT_GE(cases, 100);
  EXPECT_GT(misses, cases / 5) << "the double-precision signs decide some of them";
}

namespace {

/// Packets of N lanes over `rays` (in order, some lanes reversed, made invalid or inactive)
/// against the same tree's single rays: the same hit in every lane (the same triangle with the
/// same bits, or another one at the same distance within 1e-5), tfar its distance. Returns the
/// lanes that disagree; `ties` counts the lanes that found the other triangle.
template <int N>
int wide_packet_mismatches(const WideBvh& wide, const std::vector<Ray>& rays, TriangleTest test,
                           std::uint32_t seed, bool hard_lanes, int& ties, int& hits) {
  std::mt19937 rng(seed);
  int bad = 0;
  for (std::size_t base = 0; base + N <= rays.size(); base += N) {
    RayPacket<N> p;
    PacketHits<N> h;
    h.clear();
    bool active[N];
    for (int i = 0; i < N; ++i) {
      Ray ray = rays[base + std::size_t(i)];
      if (hard_lanes && rng() % 9 == 0) ray.direction = -ray.direction; // mixed signs
      if (hard_lanes && rng() % 13 == 0) ray.direction = vec3(0);       // invalid lane
      p.ox[i] = ray.origin.x, p.oy[i] = ray.origin.y, p.oz[i] = ray.origin.z;
      p.dx[i] = ray.direction.x, p.dy[i] = ray.direction.y, p.dz[i] = ray.direction.z;
      p.tnear[i] = ray.tnear, p.tfar[i] = ray.tfar;
      active[i] = !hard_lanes || rng() % 7 != 0;
    }
    const RayPacket<N> before = p;
    if constexpr (N == 4)
      wide.intersect4(p, h, active, test);
    else
      wide.intersect8(p, h, active, test);
    for (int i = 0; i < N; ++i) {
      PreparedRay r = PreparedRay::make(vec3(before.ox[i], before.oy[i], before.oz[i]),
                                        vec3(before.dx[i], before.dy[i], before.dz[i]),
                                        before.tnear[i], before.tfar[i]);
      TriangleHit single;
      if (active[i] && r.valid()) wide.intersect(r, single, test);
      const TriangleHit packet{h.t[i], h.u[i], h.v[i], h.prim[i]};
      hits += single.hit() ? 1 : 0;
      // Where two triangles meet, their hits lie an ulp or so apart, and which one a walk keeps
      // depends on the order it meets them (as between any two structures here): same_hit.
      const bool ok = same_hit(packet, single) && p.tfar[i] == (packet.hit() ? packet.t : r.tfar);
      if (ok && packet.prim != single.prim) ++ties;
      if (!ok && ++bad <= 3)
        ADD_FAILURE() << "N=" << N << " lane " << i << " packet prim " << packet.prim << " t "
                      << packet.t << ", single prim " << single.prim << " t " << single.t;
    }
  }
  return bad;
}

} // namespace

TEST(WideBvh, PacketsEqualSingleRaysPerLane) {
  for (const Mesh& mesh : test_meshes()) {
    SCOPED_TRACE(mesh.name);
    const TriangleView view = mesh.view();
    auto [binary, wide] = build_trees(view);
    const Aabb box = mesh_bounds(mesh);
    const auto coherent = make_rays(box, 4096, 301, true);
    const auto incoherent = make_rays(box, 4096, 303, false);
    int ties = 0, hits = 0, bad = 0;
    for (TriangleTest test : {TriangleTest::watertight, TriangleTest::moller_trumbore})
      for (const auto* rays : {&coherent, &incoherent})
        for (bool hard : {false, true}) {
          bad += wide_packet_mismatches<4>(wide, *rays, test, 305, hard, ties, hits);
          bad += wide_packet_mismatches<8>(wide, *rays, test, 307, hard, ties, hits);
        }
    EXPECT_EQ(bad, 0);
    EXPECT_GT(hits, 0);
    // Two triangles at the same distance are rare: none on the sphere and the soup, about 1.5%
    // of the hits among the degenerate mesh's needles and zero-area triangles.
    EXPECT_LE(ties, hits / 40) << ties << " ties in " << hits << " hits";
  }
}

TEST(WideBvh, PacketOcclusionEqualsSingleRaysPerLane) {
  for (const Mesh& mesh : test_meshes()) {
    SCOPED_TRACE(mesh.name);
    const TriangleView view = mesh.view();
    auto [binary, wide] = build_trees(view);
    test::expect_occlusion_packets_match(wide, view, mesh_bounds(mesh), 313);
  }
}

TEST(WideBvh, PacketsThroughSharedEdgesAndVerticesDoNotLeak) {
  // A closed sphere seen from outside: packets of rays aimed at its vertices and edge midpoints,
  // grouped so that each packet's lanes share their direction signs (the packet walk, not the
  // lane-by-lane one), must all hit, as the single rays do.
  const vec3 c(0.1f, 0.2f, -0.3f);
  const Mesh m = test::uv_sphere(24, 32, 1.0f, c, /*pole_slivers=*/false);
  const TriangleView view = m.view();
  auto [binary, wide] = build_trees(view);
  const vec3 eye = c + vec3(0.2f, 0.3f, 3.0f);
  std::vector<Ray> by_sign[4];
  for (std::uint32_t t = 0; t < view.count; ++t)
    for (int k = 0; k < 3; ++k) {
      const vec3 a = view.vertex(t, k), b = view.vertex(t, (k + 1) % 3);
      for (const vec3& target : {a, 0.5f * (a + b)}) {
        if (glm::dot(glm::normalize(target - c), glm::normalize(eye - c)) < 0.5f) continue;
        const vec3 d = target - eye;
        by_sign[(d.x < 0.0f ? 1 : 0) + (d.y < 0.0f ? 2 : 0)].push_back(Ray{eye, 0.0f, d});
      }
    }
  int rays = 0, leaks = 0;
  for (const std::vector<Ray>& group : by_sign) {
    for (std::size_t base = 0; base + 8 <= group.size(); base += 8) {
      RayPacket<8> p;
      PacketHits<8> h;
      h.clear();
      const bool active[8] = {true, true, true, true, true, true, true, true};
      for (int i = 0; i < 8; ++i) {
        const Ray& ray = group[base + std::size_t(i)];
        p.ox[i] = ray.origin.x, p.oy[i] = ray.origin.y, p.oz[i] = ray.origin.z;
        p.dx[i] = ray.direction.x, p.dy[i] = ray.direction.y, p.dz[i] = ray.direction.z;
        p.tnear[i] = ray.tnear, p.tfar[i] = ray.tfar;
      }
      wide.intersect8(p, h, active);
      for (int i = 0; i < 8; ++i) {
        ++rays;
        leaks += h.prim[i] == 0xFFFFFFFFu ? 1 : 0;
      }
    }
  }
  EXPECT_GT(rays, 1000);
  EXPECT_EQ(leaks, 0);
}
