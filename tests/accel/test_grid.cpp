// The uniform grid (engine/accel/grid): closest hits equal brute force on generated meshes with
// both triangle tests, occlusion agrees, the cell lists are exact where they must be and
// conservative elsewhere, and the resolution heuristic gives what it promises.
#include "specula/accel/grid/grid.h"

#include "accel_test_meshes.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <random>
#include <string>
#include <vector>

using namespace specula;
using namespace specula::accel;

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

using test::cube;
using test::Mesh;
using test::uv_sphere;

/// Triangles of every size in [-5, 5]^3: most small, some spanning the whole scene.
Mesh random_soup(std::uint32_t seed, int count) {
  return test::random_soup(count, seed, 5.0f,
                           [](int i) { return i % 10 == 0 ? 4.0f : (i % 3 == 0 ? 0.5f : 0.05f); });
}

/// n × n quads in the plane z = height, [-4, 4]^2.
Mesh flat_grid(int n, float height) { return test::flat_grid(n, n, -4.0f, 4.0f, height); }

/// A soup with the shared degenerate triangles mixed in: repeated vertices, collinear ones (the
/// midpoint kind once went missing from its own vertex's cell: the plane test used a normal that
/// was rounding noise), points, needles, slivers, and NaN or infinite vertices (left out of the
/// grid, never hit by brute force either).
Mesh degenerate_soup(std::uint32_t seed) {
  Mesh m = random_soup(seed, 600);
  m.name = "degenerate";
  test::add_degenerate_triangles(m, 600, seed + 1, 4.0f, 1.0f);
  return m;
}

struct Mismatches {
  int count = 0;
  int excused = 0; ///< spurious reference hits (see genuinely_hit)
  std::string first;
  void note(const std::string& what) {
    if (count++ < 5) first += what + "\n";
  }
};

std::string describe(const PreparedRay& r) {
  char buf[256];
  std::snprintf(buf, sizeof buf, "org (%.9g %.9g %.9g) dir (%.9g %.9g %.9g) [%g, %g]",
                double(r.org.x), double(r.org.y), double(r.org.z), double(r.dir.x), double(r.dir.y),
                double(r.dir.z), double(r.tnear), double(r.tfar));
  return buf;
}

template <TriangleTest Test>
bool brute_force_any(const TriangleView& tris, const PreparedRay& r) {
  if (!r.valid()) return false;
  for (std::uint32_t i = 0; i < tris.count; ++i)
    if (intersect_any<Test>(r, tris, i)) return true;
  return false;
}

/// Whether the exact ray (in double) passes through triangle `prim`, its edges widened by `slack`
/// of their barycentric range. Far from the ray's origin, Möller–Trumbore's rounding reports hits
/// on triangles the ray passes well clear of; no spatial structure reproduces those.
bool genuinely_hit(const TriangleView& tris, const PreparedRay& r, std::uint32_t prim,
                   double slack) {
  const glm::dvec3 p0(tris.vertex(prim, 0)), p1(tris.vertex(prim, 1)), p2(tris.vertex(prim, 2));
  const glm::dvec3 o(r.org), d(r.dir);
  const glm::dvec3 e1 = p1 - p0, e2 = p2 - p0, p = glm::cross(d, e2);
  const double det = glm::dot(e1, p);
  if (det == 0.0) return false;
  const glm::dvec3 s = o - p0, q = glm::cross(s, e1);
  const double u = glm::dot(s, p) / det, v = glm::dot(d, q) / det;
  return u >= -slack && v >= -slack && u + v <= 1.0 + slack;
}

/// The grid against brute force for one ray: the same hit (or an equal-t tie), r.tfar == hit.t,
/// occlusion of the full ray and of a shortened one, and the DDA never at its step bound.
/// `abs_tol` widens the tie tolerance for meshes far from the origin.
template <TriangleTest Test>
void check_ray(const UniformGrid& grid, const PreparedRay& ray, float shorten, Mismatches& bad,
               float abs_tol = 0.0f, bool excuse_spurious = false) {
  const TriangleView& tris = grid.triangles();
  const TriangleHit ref = brute_force_closest<Test>(tris, ray);
  PreparedRay r = ray;
  TriangleHit hit;
  GridTraceInfo info;
  const bool got = grid.intersect(r, hit, Test, &info);
  if (excuse_spurious && ref.hit() && hit.prim != ref.prim &&
      !genuinely_hit(tris, ray, ref.prim, 1e-3)) {
    ++bad.excused;
    return;
  }
  if (info.step_bound_hit) bad.note("step bound hit: " + describe(ray));
  if (got != ref.hit()) {
    bad.note(std::string(got ? "extra hit " : "missed hit ") + describe(ray) + " ref t " +
             std::to_string(ref.t) + " got t " + std::to_string(hit.t));
    return;
  }
  if (got) {
    if (r.tfar != hit.t) bad.note("tfar != hit.t: " + describe(ray));
    const bool same =
        hit.prim == ref.prim ? hit.t == ref.t : std::abs(hit.t - ref.t) <= 1e-5f * ref.t + abs_tol;
    if (!same)
      bad.note("hit differs: " + describe(ray) + " ref " + std::to_string(ref.prim) + " t " +
               std::to_string(ref.t) + ", got " + std::to_string(hit.prim) + " t " +
               std::to_string(hit.t));
  }
  GridTraceInfo occluded_info;
  if (grid.occluded(ray, Test, &occluded_info) != ref.hit())
    bad.note("occluded differs: " + describe(ray));
  if (occluded_info.step_bound_hit) bad.note("step bound hit (occluded): " + describe(ray));
  // A segment ending short of (or past) the closest hit: occlusion within (tnear, tfar) only.
  PreparedRay segment = ray;
  segment.tfar = ref.hit() ? ref.t * shorten : shorten * 10.0f;
  if (segment.tfar < segment.tnear) segment.tfar = segment.tnear;
  if (grid.occluded(segment, Test) != brute_force_any<Test>(tris, segment))
    bad.note("segment occlusion differs: " + describe(segment));
}

void check_rays(const UniformGrid& grid, const std::vector<PreparedRay>& rays, const char* what,
                float abs_tol = 0.0f, bool excuse_spurious_moller_trumbore = false) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> shorten(0.2f, 1.2f);
  for (const TriangleTest test : {TriangleTest::watertight, TriangleTest::moller_trumbore}) {
    Mismatches bad;
    for (const PreparedRay& r : rays) {
      if (test == TriangleTest::watertight)
        check_ray<TriangleTest::watertight>(grid, r, shorten(rng), bad, abs_tol);
      else
        check_ray<TriangleTest::moller_trumbore>(grid, r, shorten(rng), bad, abs_tol,
                                                 excuse_spurious_moller_trumbore);
    }
    // Möller–Trumbore from 1e6 away: about 8% of the reference hits are spurious.
    EXPECT_LE(bad.excused, int(rays.size()) / 5) << what << ": spurious reference hits";
    EXPECT_EQ(bad.count, 0) << what
                            << (test == TriangleTest::watertight ? " (watertight)"
                                                                 : " (Möller–Trumbore)")
                            << ", " << rays.size() << " rays:\n"
                            << bad.first;
  }
}

vec3 random_direction(std::mt19937& rng) {
  std::normal_distribution<float> normal;
  for (;;) {
    const vec3 d(normal(rng), normal(rng), normal(rng));
    const float len = glm::length(d);
    if (len > 1e-3f) return d / len;
  }
}

/// Origins anywhere in the scene's box grown by half (many inside), directions uniform.
std::vector<PreparedRay> incoherent_rays(const Aabb& box, int count, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(-0.75f, 0.75f);
  const vec3 c = box.center(), e = glm::max(box.extent(), vec3(1.0f));
  std::vector<PreparedRay> rays;
  for (int i = 0; i < count; ++i) {
    const vec3 o = c + e * vec3(unit(rng), unit(rng), unit(rng));
    rays.push_back(PreparedRay::make(o, random_direction(rng), 0.0f, kInf));
  }
  return rays;
}

/// A pinhole camera outside the scene looking at its centre: neighbouring rays, as a frame's.
std::vector<PreparedRay> coherent_rays(const Aabb& box, int side, std::uint32_t seed) {
  std::mt19937 rng(seed);
  const vec3 c = box.center();
  const float radius = std::max(glm::length(box.extent()), 1.0f);
  const vec3 eye = c + random_direction(rng) * radius * 1.5f;
  const vec3 forward = glm::normalize(c - eye);
  const vec3 right = glm::normalize(
      glm::cross(forward, std::abs(forward.y) < 0.9f ? vec3(0, 1, 0) : vec3(1, 0, 0)));
  const vec3 up = glm::cross(right, forward);
  std::vector<PreparedRay> rays;
  for (int y = 0; y < side; ++y)
    for (int x = 0; x < side; ++x) {
      const float u = (float(x) + 0.5f) / float(side) * 2.0f - 1.0f;
      const float v = (float(y) + 0.5f) / float(side) * 2.0f - 1.0f;
      rays.push_back(PreparedRay::make(eye, glm::normalize(forward + 0.6f * (u * right + v * up)),
                                       0.0f, kInf));
    }
  return rays;
}

void check_mesh(const Mesh& mesh, const char* name, std::uint32_t seed) {
  UniformGrid grid;
  grid.build(mesh.view());
  ASSERT_FALSE(grid.empty()) << name;
  const Aabb box = mesh.bounds();
  check_rays(grid, incoherent_rays(box, 6000, seed), name);
  check_rays(grid, coherent_rays(box, 80, seed + 1), name); // 6400 rays
}

} // namespace

// ---- Closest hit and occlusion against brute force
// ----------------------------------------------- Five meshes × 12 400 rays × two triangle tests (≈
// 124 000 ray queries), each also asked for occlusion of the full ray and of a segment.

TEST(UniformGrid, UvSphereMatchesBruteForce) {
  check_mesh(uv_sphere(24, 48, 2.0f, vec3(0.3f, -0.2f, 0.1f)), "uv sphere", 1);
}
TEST(UniformGrid, CubeMatchesBruteForce) { check_mesh(cube(), "cube", 2); }
TEST(UniformGrid, RandomSoupMatchesBruteForce) { check_mesh(random_soup(3, 1500), "soup", 3); }
TEST(UniformGrid, FlatGridMatchesBruteForce) { check_mesh(flat_grid(24, 0.5f), "flat grid", 4); }
TEST(UniformGrid, DegenerateTrianglesMatchBruteForce) {
  check_mesh(degenerate_soup(5), "degenerate soup", 5);
}

TEST(UniformGrid, RaysStartingInsideTheGrid) {
  const Mesh mesh = random_soup(11, 1000);
  UniformGrid grid;
  grid.build(mesh.view());
  std::mt19937 rng(12);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const Aabb b = grid.bounds();
  std::vector<PreparedRay> rays;
  for (int i = 0; i < 4000; ++i) {
    const vec3 o = b.min + b.extent() * vec3(unit(rng), unit(rng), unit(rng));
    rays.push_back(PreparedRay::make(o, random_direction(rng), 0.0f, kInf));
  }
  // And with tnear past the entry: the walk starts where the interval starts.
  for (int i = 0; i < 2000; ++i) {
    const vec3 o = b.center() - 20.0f * random_direction(rng);
    const vec3 d = glm::normalize(b.center() + vec3(unit(rng), unit(rng), unit(rng)) - o);
    rays.push_back(PreparedRay::make(o, d, 20.0f * unit(rng) + 10.0f, kInf));
  }
  check_rays(grid, rays, "inside");
}

TEST(UniformGrid, AxisParallelRays) {
  for (const Mesh& mesh :
       {random_soup(21, 1000), uv_sphere(16, 32, 3.0f, vec3(0.0f)), flat_grid(16, 0.0f)}) {
    UniformGrid grid;
    grid.build(mesh.view());
    std::mt19937 rng(22);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    const Aabb b = grid.bounds();
    std::vector<PreparedRay> rays;
    for (int i = 0; i < 3000; ++i) {
      vec3 d(0.0f);
      d[i % 3] = (i / 3) % 2 ? 1.0f : -1.0f;
      const vec3 o = b.center() + 0.6f * b.extent() * vec3(unit(rng), unit(rng), unit(rng));
      rays.push_back(PreparedRay::make(o, d, 0.0f, kInf));
    }
    check_rays(grid, rays, "axis-parallel");
  }
}

// Origins exactly on cell planes (two of them: the ray runs along a cell edge), directions along an
// axis or along a diagonal of cell faces: every tie in the DDA.
TEST(UniformGrid, RaysAlongCellBoundaries) {
  for (const Mesh& mesh : {random_soup(31, 800), flat_grid(16, 0.0f), cube()}) {
    UniformGrid grid;
    grid.build(mesh.view());
    const gpu::GridHeader& g = grid.header();
    std::mt19937 rng(32);
    std::uniform_int_distribution<int> pick(0, 1 << 20);
    std::vector<PreparedRay> rays;
    for (int i = 0; i < 4000; ++i) {
      const int axis = i % 3;
      vec3 o;
      for (int a = 0; a < 3; ++a)
        o[a] = g.bounds_min[a] + float(pick(rng) % int(g.resolution[a] + 1)) * g.cell_size;
      vec3 d(0.0f);
      if (i % 2) {
        d[axis] = (i / 3) % 2 ? 1.0f : -1.0f;
        o[axis] = (i / 3) % 2 ? g.bounds_min[axis] - 1.0f : g.bounds_max[axis] + 1.0f;
      } else { // along a face diagonal: through cell corners
        d[axis] = 1.0f;
        d[(axis + 1) % 3] = (i / 3) % 2 ? 1.0f : -1.0f;
      }
      rays.push_back(PreparedRay::make(o, d, 0.0f, kInf));
    }
    check_rays(grid, rays, "cell boundaries");
  }
}

TEST(UniformGrid, FarAwayOrigins) {
  const Mesh mesh = uv_sphere(32, 64, 2.0f, vec3(0.0f));
  UniformGrid grid;
  grid.build(mesh.view());
  std::mt19937 rng(41);
  std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
  for (const float distance : {1e5f, 1e6f}) {
    std::vector<PreparedRay> rays;
    for (int i = 0; i < 3000; ++i) {
      const vec3 o = distance * random_direction(rng);
      const vec3 target = 2.2f * vec3(unit(rng), unit(rng), unit(rng));
      rays.push_back(PreparedRay::make(o, glm::normalize(target - o), 0.0f, kInf));
    }
    // Hit distances of ~1e6 carry float steps of 0.06: ties between neighbours are that wide.
    check_rays(grid, rays, "far origin", distance * 0x1p-20f, true);
  }
}

TEST(UniformGrid, MeshesFarFromTheOrigin) {
  for (const float offset : {1e5f, 1e6f}) {
    Mesh mesh = uv_sphere(24, 48, 200.0f, vec3(0.0f));
    const Mesh soup = random_soup(51, 500);
    for (const uvec3& t : soup.triangles)
      mesh.add(soup.positions[t.x] * 30.0f, soup.positions[t.y] * 30.0f,
               soup.positions[t.z] * 30.0f);
    mesh.translate(vec3(offset, -offset, 0.5f * offset));
    UniformGrid grid;
    grid.build(mesh.view());
    const Aabb box = mesh.bounds();
    // Coordinates of 1e6 are float steps of 0.06 apart: ties are that wide.
    check_rays(grid, incoherent_rays(box, 3000, 52), "translated (incoherent)", offset * 0x1p-20f);
    check_rays(grid, coherent_rays(box, 50, 53), "translated (coherent)", offset * 0x1p-20f);
  }
}

// ---- Cell lists
// -----------------------------------------------------------------------------------

TEST(UniformGrid, CellListsAreCompleteAndNoWiderThanTriangleBoxes) {
  for (const Mesh& mesh :
       {random_soup(61, 2000), degenerate_soup(62), flat_grid(20, 1.0f), cube()}) {
    UniformGrid grid;
    grid.build(mesh.view());
    const gpu::GridHeader& g = grid.header();
    const auto starts = grid.cell_start();
    const auto indices = grid.indices();
    ASSERT_EQ(starts.size(), std::size_t(g.cell_count) + 1);
    ASSERT_EQ(starts.front(), 0u);
    ASSERT_EQ(starts.back(), indices.size());
    ASSERT_EQ(grid.stats().references, indices.size());
    EXPECT_EQ(g.cell_count, g.resolution.x * g.resolution.y * g.resolution.z);
    const auto cell_index = [&](const uvec3& c) {
      return c.x + g.resolution.x * (c.y + g.resolution.y * c.z);
    };
    const auto listed = [&](std::uint32_t cell, std::uint32_t prim) {
      return std::binary_search(indices.begin() + starts[cell], indices.begin() + starts[cell + 1],
                                prim);
    };
    // Every valid triangle is listed in the cell of each of its vertices; no invalid one anywhere.
    const TriangleView view = mesh.view();
    int unlisted = 0, invalid_listed = 0;
    std::vector<bool> valid(view.count);
    for (std::uint32_t t = 0; t < view.count; ++t) {
      valid[t] = is_finite(view.vertex(t, 0)) && is_finite(view.vertex(t, 1)) &&
                 is_finite(view.vertex(t, 2));
      if (!valid[t]) continue;
      for (int k = 0; k < 3; ++k)
        unlisted += !listed(cell_index(grid.cell_of(view.vertex(t, k))), t);
    }
    // Each cell's list is ascending, and each entry's box overlaps the cell (within the build's
    // margin, a thousandth of a cell here).
    int unsorted = 0, outside = 0;
    const float m = grid.cell_margin();
    EXPECT_LE(m, 2e-3f * g.cell_size);
    for (std::uint32_t z = 0; z < g.resolution.z; ++z)
      for (std::uint32_t y = 0; y < g.resolution.y; ++y)
        for (std::uint32_t x = 0; x < g.resolution.x; ++x) {
          const std::uint32_t c = cell_index(uvec3(x, y, z));
          const vec3 lo = g.bounds_min + vec3(float(x), float(y), float(z)) * g.cell_size - m;
          const vec3 hi = lo + g.cell_size + 2.0f * m;
          for (std::uint32_t i = starts[c]; i < starts[c + 1]; ++i) {
            if (i > starts[c] && indices[i - 1] >= indices[i]) ++unsorted;
            const std::uint32_t t = indices[i];
            if (t >= view.count || !valid[t]) {
              ++invalid_listed;
              continue;
            }
            const Aabb tb = view.bounds(t);
            outside +=
                glm::any(glm::lessThan(tb.max, lo)) || glm::any(glm::greaterThan(tb.min, hi));
          }
        }
    EXPECT_EQ(unlisted, 0);
    EXPECT_EQ(invalid_listed, 0);
    EXPECT_EQ(unsorted, 0);
    EXPECT_EQ(outside, 0);
  }
}

// The separating-axis refinement: a long diagonal triangle is listed in far fewer cells than its
// box covers, yet in every cell a ray finds it through.
TEST(UniformGrid, DiagonalTriangleIsNotListedInEveryCellOfItsBox) {
  Mesh mesh = random_soup(71, 4000);
  mesh.add(vec3(-5, -5, -5), vec3(5, 5, 5), vec3(5, 5, 4.5f));
  const auto big = std::uint32_t(mesh.triangles.size() - 1);
  UniformGrid grid;
  grid.build(mesh.view());
  const gpu::GridHeader& g = grid.header();
  std::uint32_t listed = 0;
  for (std::uint32_t c = 0; c < g.cell_count; ++c)
    listed += std::binary_search(grid.indices().begin() + grid.cell_start()[c],
                                 grid.indices().begin() + grid.cell_start()[c + 1], big);
  const uvec3 lo = grid.cell_of(vec3(-5.0f)), hi = grid.cell_of(vec3(5.0f));
  const uvec3 span = hi - lo + 1u;
  EXPECT_LT(listed, span.x * span.y * span.z / 4)
      << "listed in " << listed << " of " << span.x * span.y * span.z;
  EXPECT_GE(listed, std::max({span.x, span.y, span.z}));
}

TEST(UniformGrid, BuildIsDeterministic) {
  const Mesh mesh = random_soup(81, 5000);
  UniformGrid a, b;
  a.build(mesh.view());
  b.build(mesh.view());
  EXPECT_TRUE(std::equal(a.cell_start().begin(), a.cell_start().end(), b.cell_start().begin(),
                         b.cell_start().end()));
  EXPECT_TRUE(
      std::equal(a.indices().begin(), a.indices().end(), b.indices().begin(), b.indices().end()));
}

// ---- Resolution heuristic
// -------------------------------------------------------------------------

TEST(UniformGrid, ResolutionGivesCubicalCellsNearTheTargetCount) {
  struct Case {
    Mesh mesh;
    const char* name;
  };
  const Case cases[] = {{uv_sphere(32, 64, 2.0f, vec3(0.0f)), "sphere"},
                        {random_soup(91, 3000), "soup"},
                        {flat_grid(40, 0.0f), "flat grid"}};
  for (const Case& c : cases) {
    for (const float density : {1.0f, 4.0f, 8.0f}) {
      UniformGrid grid;
      grid.build(c.mesh.view(), GridBuildOptions{density});
      const gpu::GridHeader& g = grid.header();
      const double target = double(density) * double(c.mesh.triangles.size());
      const double ratio = double(g.cell_count) / target;
      EXPECT_GT(ratio, 0.5) << c.name << " density " << density << ": " << g.cell_count << " cells";
      EXPECT_LT(ratio, 2.0) << c.name << " density " << density << ": " << g.cell_count << " cells";
      // Cubical: one side for all axes, the box exactly res · side, covering the triangles.
      const vec3 span = g.bounds_max - g.bounds_min;
      for (int a = 0; a < 3; ++a) {
        EXPECT_NEAR(span[a], float(g.resolution[a]) * g.cell_size, 1e-4f * span[a] + 1e-6f);
        EXPECT_LT(float(g.resolution[a] - 1) * g.cell_size,
                  std::max(c.mesh.bounds().extent()[a], 1e-30f) + 1e-4f)
            << "a whole empty cell of padding on axis " << a;
      }
      EXPECT_TRUE(glm::all(glm::lessThanEqual(g.bounds_min, c.mesh.bounds().min)));
      EXPECT_TRUE(glm::all(glm::greaterThanEqual(g.bounds_max, c.mesh.bounds().max)));
      EXPECT_FLOAT_EQ(g.inv_cell_size, 1.0f / g.cell_size);
    }
  }
}

TEST(UniformGrid, FlatSceneGetsOneCellAcrossItsPlane) {
  const Mesh mesh = flat_grid(40, 2.0f); // z = 2 everywhere
  UniformGrid grid;
  grid.build(mesh.view());
  const gpu::GridHeader& g = grid.header();
  EXPECT_EQ(g.resolution.z, 1u);
  EXPECT_EQ(g.resolution.x, g.resolution.y);
  EXPECT_LT(g.bounds_min.z, 2.0f);
  EXPECT_GT(g.bounds_max.z, 2.0f);
}

TEST(UniformGrid, ResolutionIsClamped) {
  const Mesh sphere = uv_sphere(32, 64, 2.0f, vec3(0.0f));
  UniformGrid grid;
  grid.build(sphere.view(), GridBuildOptions{4.0f, 1000});
  EXPECT_LE(grid.header().cell_count, 1000u);
  EXPECT_GT(grid.header().cell_count, 300u);
  // A long thin strip: the length alone would ask for 40 000 cells along x.
  Mesh strip;
  for (int i = 0; i < 10000; ++i) {
    const float x = float(i) * 0.1f;
    strip.add(vec3(x, 0, 0), vec3(x + 0.1f, 0, 0), vec3(x, 0.001f, 0));
  }
  grid.build(strip.view());
  EXPECT_EQ(grid.header().resolution.x, kGridMaxAxisResolution);
  check_rays(grid, incoherent_rays(strip.bounds(), 500, 92), "strip");
}

// ---- Edge cases
// -----------------------------------------------------------------------------------

TEST(UniformGrid, InvalidRaysMiss) {
  const Mesh mesh = uv_sphere(8, 16, 1.0f, vec3(0.0f));
  UniformGrid grid;
  grid.build(mesh.view());
  const PreparedRay rays[] = {
      PreparedRay::make(vec3(kNaN, 0, 5), vec3(0, 0, -1), 0.0f, kInf),
      PreparedRay::make(vec3(0, 0, 5), vec3(0, kNaN, -1), 0.0f, kInf),
      PreparedRay::make(vec3(0, 0, 5), vec3(0, 0, 0), 0.0f, kInf),
      PreparedRay::make(vec3(0, 0, 5), vec3(0, kInf, -1), 0.0f, kInf),
      PreparedRay::make(vec3(kInf, 0, 5), vec3(0, 0, -1), 0.0f, kInf),
      PreparedRay::make(vec3(0, 0, 5), vec3(0, 0, -1), 3.0f, 2.0f),
      PreparedRay::make(vec3(0, 0, 5), vec3(0, 0, -1), -1.0f, kInf),
      PreparedRay::make(vec3(0, 0, 5), vec3(0, 0, -1), kNaN, kInf),
      PreparedRay::make(vec3(0, 0, 5), vec3(0, 0, -1), 0.0f, kNaN),
      PreparedRay::make(vec3(0, 0, 5), vec3(0, 0, -1), kInf, kInf),
  };
  for (const PreparedRay& ray : rays) {
    PreparedRay r = ray;
    TriangleHit hit;
    EXPECT_FALSE(grid.intersect(r, hit)) << describe(ray);
    EXPECT_FALSE(hit.hit());
    EXPECT_FALSE(grid.occluded(ray)) << describe(ray);
    EXPECT_FALSE(grid.occluded(ray, TriangleTest::moller_trumbore)) << describe(ray);
  }
  // The same ray, valid, hits.
  PreparedRay r = PreparedRay::make(vec3(0.01f, 0.02f, 5), vec3(0, 0, -1), 0.0f, kInf);
  TriangleHit hit;
  EXPECT_TRUE(grid.intersect(r, hit));
}

TEST(UniformGrid, EmptyAndUnusableInputsGiveAnEmptyGrid) {
  UniformGrid grid;
  grid.build(TriangleView{});
  EXPECT_TRUE(grid.empty());
  EXPECT_TRUE(grid.bounds().empty());
  EXPECT_TRUE(grid.cell_start().empty());
  EXPECT_TRUE(grid.indices().empty());
  PreparedRay r = PreparedRay::make(vec3(0.0f), vec3(0, 0, -1), 0.0f, kInf);
  TriangleHit hit;
  EXPECT_FALSE(grid.intersect(r, hit));
  EXPECT_FALSE(grid.occluded(r));

  Mesh nan_only;
  nan_only.add(vec3(kNaN), vec3(0.0f), vec3(1.0f));
  nan_only.add(vec3(0.0f), vec3(kInf, 0, 0), vec3(1.0f));
  grid.build(nan_only.view());
  EXPECT_TRUE(grid.empty());
  EXPECT_FALSE(grid.intersect(r, hit));

  // Rebuilding a used grid over something valid works.
  const Mesh box = cube();
  grid.build(box.view());
  EXPECT_FALSE(grid.empty());
  r = PreparedRay::make(vec3(0.1f, 0.2f, 5), vec3(0, 0, -1), 0.0f, kInf);
  EXPECT_TRUE(grid.intersect(r, hit));
  EXPECT_FLOAT_EQ(hit.t, 4.0f);
}

TEST(UniformGrid, SinglePointAndHugeCoordinatesDoNotBreakTheBuild) {
  Mesh point;
  point.add(vec3(1.0f), vec3(1.0f), vec3(1.0f));
  UniformGrid grid;
  grid.build(point.view());
  EXPECT_FALSE(grid.empty());
  EXPECT_EQ(grid.header().cell_count, 1u);
  EXPECT_GT(grid.header().cell_size, 0.0f);

  // Beyond kGridMaxCoordinate: left out (neither triangle test can hit it: its products overflow).
  // Within it but huge: kept, and the cube's cells still work.
  Mesh huge = cube();
  huge.add(vec3(-3e38f, 0, 0), vec3(3e38f, 0, 0), vec3(0, 3e38f, 1));
  huge.add(vec3(-1e17f, 0, 50), vec3(1e17f, 0, 50), vec3(0, 1e17f, 51));
  grid.build(huge.view());
  EXPECT_FALSE(grid.empty());
  EXPECT_LT(grid.bounds().min.x, -0.9e17f);
  EXPECT_TRUE(is_finite(grid.bounds().max));
  check_rays(grid, incoherent_rays(cube().bounds(), 300, 101), "huge");
}

TEST(UniformGrid, StatsDescribeTheArrays) {
  const Mesh mesh = random_soup(111, 2000);
  UniformGrid grid;
  grid.build(mesh.view());
  const GridStats& s = grid.stats();
  EXPECT_EQ(s.cells, grid.header().cell_count);
  EXPECT_EQ(s.references, grid.indices().size());
  EXPECT_GE(s.references, 2000u);
  std::uint32_t empty = 0;
  for (std::uint32_t c = 0; c < s.cells; ++c)
    empty += grid.cell_start()[c] == grid.cell_start()[c + 1];
  EXPECT_EQ(s.empty_cells, empty);
  EXPECT_FLOAT_EQ(s.avg_per_nonempty,
                  float(double(s.references) / double(s.cells - s.empty_cells)));
  EXPECT_EQ(s.bytes,
            sizeof(gpu::GridHeader) + 4 * (grid.cell_start().size() + grid.indices().size()));
  EXPECT_GE(s.build_ms, 0.0);
}
