// Kernel tests: one piece of the device traversal dispatched alone on small inputs and compared
// with the CPU function it mirrors.
//   - probe_grid_cells.comp: the cells trace.glsl's 3D-DDA enters, ray by ray, against the cells
//     UniformGrid::traverse visits (GridTraceInfo::cells): identical sequences, on seeded random
//     rays and on the DDA's hard cases (rays along axes, through cell faces, edges and corners,
//     from inside and outside the grid, parallel to faces, tiny and huge directions).
//   - probe_triangle.comp: ray_triangle.glsl's watertight test against accel::intersect_watertight
//     on hits at edges and vertices, shared edges, degenerate and sliver triangles, huge and tiny
//     coordinates, rays in the triangle's plane: the same hit/miss and bit-identical t, u, v.
//   - the build's SPIR-V (no device): every floating-point operation of every shader is decorated
//     NoContraction (shaders/tools/spv_exact.cpp), the premise of the two above.
#include "scene_builder.h"

#include "specula/accel/grid/grid.h"
#include "specula/core/error.h"
#include "specula/gpu/shaders.h"
#include "specula/gpu/vulkan_tracer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace specula::gpu {
namespace {

std::unique_ptr<VulkanTracer> try_vulkan(const VulkanOptions& options) {
  try {
    return std::make_unique<VulkanTracer>(8, options);
  } catch (const UnavailableError&) {
    return nullptr;
  }
}

std::string describe(const Ray& r) {
  std::ostringstream s;
  s.precision(9);
  s << "org (" << r.origin.x << ", " << r.origin.y << ", " << r.origin.z << ") dir ("
    << r.direction.x << ", " << r.direction.y << ", " << r.direction.z << ") t (" << r.tnear
    << ", " << r.tfar << ")";
  return s.str();
}

// ---- Grid DDA --------------------------------------------------------------------------------------

/// Small triangles scattered over [-1, 1]³ (seeded): most cells empty, so walks are long.
TriangleMesh scattered_triangles(std::uint32_t n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> pos(-1.0f, 1.0f), off(-0.08f, 0.08f);
  TriangleMesh m;
  for (std::uint32_t i = 0; i < n; ++i) {
    const vec3 c(pos(rng), pos(rng), pos(rng));
    for (int k = 0; k < 3; ++k) m.positions.push_back(c + vec3(off(rng), off(rng), off(rng)));
    m.triangles.emplace_back(3 * i, 3 * i + 1, 3 * i + 2);
  }
  return m;
}

/// The DDA's hard cases on grid `g`, plus seeded random rays from inside and outside it.
std::vector<Ray> grid_rays(const GridHeader& g, std::uint32_t seed) {
  std::vector<Ray> rays;
  const auto add = [&](vec3 o, vec3 d, float tnear = 0.0f,
                       float tfar = std::numeric_limits<float>::infinity()) {
    rays.push_back(Ray{o, tnear, d, tfar});
  };
  const vec3 lo = g.bounds_min, hi = g.bounds_max;
  const vec3 mid = 0.5f * (lo + hi);
  const float cs = g.cell_size;
  // A grid vertex (cell corner), a point on a cell edge and one on a cell face, all interior.
  const vec3 corner = lo + cs * vec3(g.resolution / 2u);
  const vec3 on_edge = corner + vec3(0.0f, 0.0f, 0.37f * cs);
  const vec3 on_face = corner + vec3(0.0f, 0.41f * cs, 0.23f * cs);
  for (int a = 0; a < 3; ++a) {
    for (const float sign : {1.0f, -1.0f}) {
      vec3 d(0.0f);
      d[a] = sign;
      for (const vec3& p : {mid, corner, on_edge, on_face, lo, hi}) {
        add(p, d);                    // along an axis, from inside (or on the grid's box)
        add(p - 3.0f * (hi - lo) * d, d); // from outside, through the same point
      }
      vec3 diag(1.0f);
      diag[a] = sign;
      add(corner, diag);                       // through cell corners all the way
      add(corner - 5.0f * cs * diag, diag);    // entering at a corner from outside
      vec3 in_plane = diag;
      in_plane[(a + 1) % 3] = 0.0f;            // parallel to a family of faces, on a face
      add(on_face, in_plane);
      add(corner, in_plane);
      add(lo, diag * 1e-30f);                  // tiny and huge directions
      add(mid, vec3(d.x + 1e-38f, d.y + 3e-39f, d.z - 1e-39f)); // denormal components
      add(mid - 1e30f * diag, diag * 1e30f);
      add(mid, diag, 0.5f, 0.5f + 3.0f * cs);  // an interval ending inside the grid
    }
  }
  add(hi + vec3(cs), vec3(1.0f, 0.5f, 0.25f)); // pointing away from the grid
  add(lo - vec3(cs, 0.0f, 0.0f), vec3(0.0f, 1.0f, 0.0f)); // parallel, beside the grid
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> uni(-1.0f, 1.0f);
  const vec3 half = 0.5f * (hi - lo);
  for (int i = 0; i < 400; ++i) {
    const float reach = i % 2 == 0 ? 0.9f : 2.5f; // inside, then mostly outside
    const vec3 o = mid + reach * half * vec3(uni(rng), uni(rng), uni(rng));
    const vec3 target = mid + half * vec3(uni(rng), uni(rng), uni(rng));
    const vec3 d = target - o;
    if (glm::length(d) > 0.0f) add(o, i % 3 == 0 ? glm::normalize(d) : d);
  }
  return rays;
}

// Result ids of float arithmetic, and the ids decorated NoContraction, in a SPIR-V module.
struct FloatOps {
  std::vector<std::uint32_t> results;
  std::vector<std::uint32_t> exact;
};

FloatOps float_ops(std::span<const std::uint32_t> words) {
  FloatOps ops;
  for (std::size_t i = 5; i < words.size();) {
    const std::uint32_t count = words[i] >> 16, op = words[i] & 0xFFFFu;
    if (count == 0 || i + count > words.size()) throw Error("spirv", "truncated module");
    // OpFNegate, OpFAdd, OpFSub, OpFMul, OpFDiv, OpFRem, OpFMod, OpVectorTimesScalar ... OpDot.
    const bool arithmetic =
        op == 127 || op == 129 || op == 131 || op == 133 || op == 136 || (op >= 140 && op <= 148);
    if (arithmetic) ops.results.push_back(words[i + 2]);
    if (op == 71 && count >= 3 && words[i + 2] == 42)
      ops.exact.push_back(words[i + 1]); // OpDecorate
    i += count;
  }
  return ops;
}

TEST(GpuKernels, EveryFloatingPointOperationOfEveryShaderRoundsOnItsOwn) {
  std::size_t checked = 0;
  for (const std::string_view name : shader_names()) {
    const FloatOps ops = float_ops(shader_spirv(name));
    for (const std::uint32_t id : ops.results) {
      EXPECT_NE(std::find(ops.exact.begin(), ops.exact.end(), id), ops.exact.end())
          << name << ": float operation %" << id << " may be fused (no NoContraction)";
      ++checked;
    }
  }
  // The traversal's own kernel has the watertight test's arithmetic, at least.
  EXPECT_GE(float_ops(shader_spirv("trace_rays")).results.size(), 50u);
  EXPECT_GT(checked, 1000u);
}

TEST(GpuKernels, TheGridDdaEntersTheSameCellsAsTheCpuDda) {
  VulkanOptions o;
  o.structure = GpuStructure::grid;
  o.grid_density = 24.0f;
  auto gpu = try_vulkan(o);
  if (!gpu) GTEST_SKIP() << "no Vulkan device on this machine";
  ecs::Registry reg;
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e, test::at(vec3(0.0f)));
  reg.emplace<Mesh>(e, Mesh{std::make_shared<const TriangleMesh>(scattered_triangles(150, 17)), {}, {}, 0});
  reg.emplace<Material>(e);
  reg.emplace<Kinematics>(e, Kinematics{Kinematics::Type::Static});
  update_world_transforms(reg, 1);
  SceneLayer layer;
  layer.sync(reg);
  gpu->update(layer);
  const accel::UniformGrid& grid = gpu->scene().native().grid();
  const GridHeader& g = grid.header();
  ASSERT_GE(std::min({g.resolution.x, g.resolution.y, g.resolution.z}), 8u);
  const std::vector<Ray> rays = grid_rays(g, 29);

  Context& ctx = gpu->context();
  const std::uint32_t n = std::uint32_t(rays.size());
  const std::uint32_t max_cells = g.resolution.x + g.resolution.y + g.resolution.z + 3;
  Buffer ray_buf = ctx.make_buffer(rays.size() * sizeof(Ray));
  Buffer cell_buf = ctx.make_buffer(std::size_t(n) * max_cells * 4);
  Buffer walk_buf = ctx.make_buffer(std::size_t(n) * 8);
  ray_buf.upload(rays.data(), rays.size() * sizeof(Ray));
  const Pipeline probe = ctx.make_pipeline({shader_spirv("probe_grid_cells"),
                                            kSceneBindings + 3,
                                            12,
                                            {},
                                            "probe_grid_cells",
                                            GpuScene::texel_bindings()});
  struct {
    std::uint32_t ray_count, budget, max_cells;
  } push{n, 2048, max_cells}; // 8 rays × 2048 steps stay under lavapipe's shared loop cap
  std::vector<const Buffer*> buffers(gpu->scene().bindings().begin(), gpu->scene().bindings().end());
  buffers.insert(buffers.end(), {&ray_buf, &cell_buf, &walk_buf});
  Commands cmd(ctx);
  cmd.fill(walk_buf, kRayPending);
  cmd.barrier();
  cmd.dispatch(probe, std::span<const Buffer* const>(buffers), &push, (n + 7) / 8);
  cmd.submit();
  std::vector<std::uint32_t> cells(std::size_t(n) * max_cells), walks(std::size_t(n) * 2);
  cell_buf.download(std::span<std::uint32_t>(cells));
  walk_buf.download(std::span<std::uint32_t>(walks));

  std::size_t walked = 0, long_walks = 0;
  for (std::uint32_t i = 0; i < n; ++i) {
    ASSERT_EQ(walks[2 * i], kRayDone) << "ray " << i << " not finished (cut or out of budget)";
    std::vector<std::uint32_t> expected;
    accel::GridTraceInfo info;
    info.cells = &expected;
    accel::PreparedRay r = accel::PreparedRay::make(rays[i]);
    accel::TriangleHit hit;
    (void)grid.intersect(r, hit, accel::TriangleTest::watertight, &info);
    const std::uint32_t count = walks[2 * i + 1];
    ASSERT_LE(count, max_cells);
    const std::vector<std::uint32_t> got(cells.begin() + std::ptrdiff_t(i) * max_cells,
                                         cells.begin() + std::ptrdiff_t(i) * max_cells + count);
    EXPECT_EQ(got, expected) << "ray " << i << ": " << describe(rays[i]);
    walked += expected.empty() ? 0 : 1;
    long_walks += expected.size() >= 8 ? 1 : 0;
  }
  // The cases exercise the walk: most rays cross the grid, many over several cells.
  EXPECT_GT(walked, rays.size() / 2);
  EXPECT_GT(long_walks, rays.size() / 4);
}

// ---- Ray/triangle ----------------------------------------------------------------------------------

struct TriangleCase {
  Ray ray;
  std::array<vec3, 3> p;
};

struct TriangleResult {
  bool hit;
  float t, u, v;
};

/// Runs probe_triangle.comp over the cases.
std::vector<TriangleResult> gpu_triangles(Context& ctx, const std::vector<TriangleCase>& cases) {
  const std::uint32_t n = std::uint32_t(cases.size());
  std::vector<Ray> rays;
  std::vector<float> corners;
  for (const TriangleCase& c : cases) {
    rays.push_back(c.ray);
    for (const vec3& p : c.p) corners.insert(corners.end(), {p.x, p.y, p.z});
  }
  Buffer ray_buf = ctx.make_buffer(rays.size() * sizeof(Ray));
  Buffer tri_buf = ctx.make_buffer(corners.size() * 4);
  Buffer out_buf = ctx.make_buffer(std::size_t(n) * 16);
  ray_buf.upload(rays.data(), rays.size() * sizeof(Ray));
  tri_buf.upload(corners.data(), corners.size() * 4);
  const Pipeline probe =
      ctx.make_pipeline({shader_spirv("probe_triangle"), 3, 4, {}, "probe_triangle"});
  Commands cmd(ctx);
  cmd.dispatch(probe, {&ray_buf, &tri_buf, &out_buf}, &n, (n + 7) / 8);
  cmd.submit();
  std::vector<std::uint32_t> words(std::size_t(n) * 4);
  out_buf.download(std::span<std::uint32_t>(words));
  std::vector<TriangleResult> out(n);
  for (std::uint32_t i = 0; i < n; ++i)
    out[i] = {words[4 * i] != 0, std::bit_cast<float>(words[4 * i + 1]),
              std::bit_cast<float>(words[4 * i + 2]), std::bit_cast<float>(words[4 * i + 3])};
  return out;
}

TriangleResult cpu_triangle(const TriangleCase& c) {
  const accel::PreparedRay r = accel::PreparedRay::make(c.ray);
  TriangleResult out{false, 0.0f, 0.0f, 0.0f};
  out.hit = accel::intersect_watertight(r, c.p[0], c.p[1], c.p[2], r.tfar, out.t, out.u, out.v);
  return out;
}

bool same_bits(float a, float b) { return std::bit_cast<std::uint32_t>(a) == std::bit_cast<std::uint32_t>(b); }

/// Rays from `from` through `target`, the triangle given.
void aim(std::vector<TriangleCase>& cases, const std::array<vec3, 3>& p, const vec3& from,
         const vec3& target) {
  cases.push_back({Ray{from, 0.0f, target - from, std::numeric_limits<float>::infinity()}, p});
}

/// Targets on a triangle's vertices, edges (midpoints and random points) and interior, from
/// origins on both sides, along each dominant axis and its negative.
void hard_cases(std::vector<TriangleCase>& cases, const std::array<vec3, 3>& p, std::mt19937& rng) {
  std::uniform_real_distribution<float> uni(0.0f, 1.0f);
  const vec3 centroid = (p[0] + p[1] + p[2]) / 3.0f;
  const float size = glm::length(p[1] - p[0]) + glm::length(p[2] - p[0]);
  std::vector<vec3> targets = {p[0], p[1], p[2], centroid};
  for (int e = 0; e < 3; ++e) {
    const vec3 a = p[e], b = p[(e + 1) % 3];
    targets.push_back(0.5f * (a + b));
    for (int k = 0; k < 3; ++k) targets.push_back(glm::mix(a, b, uni(rng)));
  }
  const vec3 offsets[] = {vec3(0.1f, 0.2f, 1.0f),  vec3(-0.3f, 0.1f, -1.0f), vec3(1.0f, 0.2f, -0.1f),
                          vec3(-1.0f, 0.3f, 0.2f), vec3(0.2f, 1.0f, 0.3f),   vec3(0.1f, -1.0f, -0.2f)};
  for (const vec3& t : targets)
    for (const vec3& off : offsets) aim(cases, p, t + size * off, t);
  // In the triangle's plane: along each edge from beyond its end, and across it.
  for (int e = 0; e < 3; ++e) {
    const vec3 a = p[e], b = p[(e + 1) % 3];
    aim(cases, p, a + 2.0f * (a - b), b);
    aim(cases, p, 2.0f * a - centroid, centroid);
  }
}

TEST(GpuKernels, TheWatertightTestGivesTheCpuResultsToTheBit) {
  auto gpu = try_vulkan({});
  if (!gpu) GTEST_SKIP() << "no Vulkan device on this machine";
  std::mt19937 rng(41);
  std::uniform_real_distribution<float> uni(-1.0f, 1.0f);
  std::vector<TriangleCase> cases;
  using Tri = std::array<vec3, 3>;
  const std::vector<Tri> shapes = {
      {vec3(0, 0, 0), vec3(1, 0, 0), vec3(0, 1, 0)},                     // axis-aligned
      {vec3(0.3f, -0.2f, 0.7f), vec3(1.1f, 0.4f, -0.3f), vec3(-0.5f, 0.9f, 0.2f)},
      {vec3(0, 0, 0), vec3(1, 0, 0), vec3(1e-7f, 1.0f, 0)},               // sliver
      {vec3(0, 0, 0), vec3(1, 1e-6f, 0), vec3(2, 2e-6f, 1e-7f)},          // near-degenerate
      {vec3(0, 0, 0), vec3(1, 1, 1), vec3(2, 2, 2)},                      // collinear
      {vec3(0.5f), vec3(0.5f), vec3(0.5f)},                               // a point
      {vec3(1e30f, 0, 0), vec3(0, 1e30f, 0), vec3(0, 0, 1e30f)},          // huge
      {vec3(1e19f, 2e19f, -1e19f), vec3(3e19f, -1e19f, 2e19f), vec3(-2e19f, 1e19f, 1e19f)},
      {vec3(1e-30f, 0, 0), vec3(0, 1e-30f, 0), vec3(0, 0, 1e-30f)},       // tiny
      {vec3(1e6f, 1e6f, 1e6f), vec3(1e6f + 1, 1e6f, 1e6f), vec3(1e6f, 1e6f + 1, 1e6f + 1)}, // far
  };
  for (const Tri& t : shapes) hard_cases(cases, t, rng);
  // Seeded random triangles and rays, some with an interval that ends before or around the hit.
  for (int i = 0; i < 300; ++i) {
    const Tri t = {vec3(uni(rng), uni(rng), uni(rng)), vec3(uni(rng), uni(rng), uni(rng)),
                   vec3(uni(rng), uni(rng), uni(rng))};
    hard_cases(cases, t, rng);
    cases.back().ray.tnear = 0.5f;
    cases[cases.size() - 2].ray.tfar = 1.0f;
  }
  // Two triangles sharing the diagonal of a quad, rays through points of the shared edge.
  const vec3 a(-0.4f, -0.3f, 0.2f), b(0.6f, -0.35f, 0.1f), c(0.5f, 0.55f, -0.2f), d(-0.45f, 0.5f, 0.0f);
  const Tri left = {a, b, c}, right = {a, c, d};
  const std::size_t shared_first = cases.size();
  for (int i = 0; i < 200; ++i) {
    const vec3 on_edge = glm::mix(a, c, 0.5f * (uni(rng) + 1.0f));
    const vec3 from = on_edge + vec3(0.3f * uni(rng), 0.3f * uni(rng), i % 2 == 0 ? 2.0f : -2.0f);
    aim(cases, left, from, on_edge);
    aim(cases, right, from, on_edge);
  }

  const std::vector<TriangleResult> got = gpu_triangles(gpu->context(), cases);
  std::size_t hits = 0, edge_hits = 0;
  for (std::size_t i = 0; i < cases.size(); ++i) {
    const TriangleResult want = cpu_triangle(cases[i]);
    ASSERT_EQ(got[i].hit, want.hit) << "case " << i << ": " << describe(cases[i].ray);
    if (!want.hit) continue;
    ++hits;
    EXPECT_TRUE(same_bits(got[i].t, want.t) && same_bits(got[i].u, want.u) &&
                same_bits(got[i].v, want.v))
        << "case " << i << ": gpu t " << got[i].t << " u " << got[i].u << " v " << got[i].v
        << ", cpu t " << want.t << " u " << want.u << " v " << want.v;
    edge_hits += (want.u == 0.0f || want.v == 0.0f || want.u + want.v == 1.0f) ? 1 : 0;
  }
  EXPECT_GT(hits, cases.size() / 4);
  EXPECT_GT(edge_hits, 0u); // some hits lie exactly on an edge (an edge function of 0)
  // Watertight: no ray through the shared edge slips between the two triangles.
  for (std::size_t i = shared_first; i < cases.size(); i += 2)
    EXPECT_TRUE(got[i].hit || got[i + 1].hit) << "ray through the shared edge missed both: case "
                                              << i << ": " << describe(cases[i].ray);
}

} // namespace
} // namespace specula::gpu
