// GPU traversal (shaders/include/trace.glsl, trace_rays.comp, GpuScene, VulkanTracer) against the
// native backend it mirrors: the same structures walked the same way must give bit-identical hits
// (t, barycentrics, instance, primitive, normal) — on the bunny with random rays, at triangle edges
// and vertices and on grazing rays, on both levels, with a grid of any density, and with a
// traversal budget so small that every ray is resumed many times. Updates follow the scene
// layer's delta (nothing uploaded for an unchanged frame, only the top level for moved instances),
// and a lost device surfaces as a GpuError.
#include "scene_builder.h"

#include "specula/accel/native/native_tracer.h"
#include "specula/core/error.h"
#include "specula/gpu/vulkan_tracer.h"
#include "specula/render/render_job.h"
#include "specula/scene/mesh_io.h"
#include "specula/systems/schedule.h"

#include <gtest/gtest.h>

#include <bit>
#include <filesystem>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

namespace specula::gpu {
namespace {

std::unique_ptr<VulkanTracer> try_vulkan(const VulkanOptions& options = {}) {
  try {
    return std::make_unique<VulkanTracer>(8, options);
  } catch (const UnavailableError&) {
    return nullptr;
  }
}

#define SPECULA_NEED_VULKAN(var, options)                                                          \
  auto var = try_vulkan(options);                                                                  \
  if (!var) GTEST_SKIP() << "no Vulkan device on this machine"

NativeOptions native_like(const VulkanOptions& o) {
  NativeOptions n;
  n.static_structure = o.structure == GpuStructure::grid ? StaticStructure::grid : StaticStructure::bvh;
  n.wide_bvh = false; // the binary tree, as the device walks it
  n.grid_density = o.grid_density;
  return n;
}

bool same_bits(float a, float b) { return std::bit_cast<std::uint32_t>(a) == std::bit_cast<std::uint32_t>(b); }

bool identical(const Hit& a, const Hit& b) {
  if (a.instance != b.instance) return false;
  if (!a.hit()) return true;
  return a.primitive == b.primitive && same_bits(a.t, b.t) && same_bits(a.uv.x, b.uv.x) &&
         same_bits(a.uv.y, b.uv.y) && same_bits(a.object_normal.x, b.object_normal.x) &&
         same_bits(a.object_normal.y, b.object_normal.y) &&
         same_bits(a.object_normal.z, b.object_normal.z);
}

std::string describe(const Hit& h) {
  std::ostringstream s;
  s.precision(9);
  s << "{inst " << h.instance << " prim " << h.primitive << " t " << h.t << " uv " << h.uv.x << ","
    << h.uv.y << "}";
  return s.str();
}

struct Agreement {
  std::size_t rays = 0, identical = 0, hits = 0;
  std::string first_difference;
};

/// Traces `rays` on both tracers and compares hit by hit (and occlusion, which must agree fully).
Agreement compare(const Tracer& gpu, const Tracer& native, const std::vector<Ray>& rays) {
  std::vector<Hit> a(rays.size()), b(rays.size());
  gpu.intersect(rays, a);
  native.intersect(rays, b);
  Agreement out;
  out.rays = rays.size();
  for (std::size_t i = 0; i < rays.size(); ++i) {
    out.hits += b[i].hit() ? 1 : 0;
    if (identical(a[i], b[i])) {
      ++out.identical;
    } else if (out.first_difference.empty()) {
      out.first_difference = "ray " + std::to_string(i) + ": gpu " + describe(a[i]) + " native " +
                             describe(b[i]);
    }
  }
  std::vector<std::uint8_t> oa(rays.size()), ob(rays.size());
  gpu.occluded(rays, oa);
  native.occluded(rays, ob);
  EXPECT_EQ(oa, ob) << "occlusion differs";
  return out;
}

/// Rays from a sphere of radius `r` around `center` aimed at random points of the box
/// center ± half (most hit), plus one in eight in random directions.
std::vector<Ray> random_rays(std::size_t n, const vec3& center, const vec3& half, float r,
                             std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> uni(-1.0f, 1.0f);
  const auto unit = [&] {
    for (;;) {
      const vec3 v(uni(rng), uni(rng), uni(rng));
      const float l = glm::length(v);
      if (l > 0.1f && l <= 1.0f) return v / l;
    }
  };
  std::vector<Ray> rays(n);
  for (std::size_t i = 0; i < n; ++i) {
    Ray& ray = rays[i];
    ray.origin = center + r * unit();
    const vec3 target = center + half * vec3(uni(rng), uni(rng), uni(rng));
    ray.direction = i % 8 == 7 ? unit() : glm::normalize(target - ray.origin);
  }
  return rays;
}

std::shared_ptr<const TriangleMesh> bunny() {
  static const auto mesh = std::make_shared<const TriangleMesh>(
      load_mesh_file(std::filesystem::path(SPECULA_SOURCE_DIR) / "samples/models/bunny.obj"));
  return mesh;
}

ecs::Entity add(ecs::Registry& reg, std::shared_ptr<const TriangleMesh> mesh, const Transform& t,
                Kinematics::Type kinematics) {
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e, t);
  reg.emplace<Mesh>(e, Mesh{std::move(mesh), {}, {}, 0});
  reg.emplace<Material>(e);
  reg.emplace<Kinematics>(e, Kinematics{kinematics});
  return e;
}

/// The bunny static at the origin, a rotated and scaled bunny instance and a box beside it
/// (dynamic: the top level and per-mesh BVHs), synced into one layer both tracers read.
struct BunnyWorld {
  ecs::Registry reg;
  SceneLayer layer;
  vec3 center{0.0f}, half{0.0f};
  float radius = 0.0f;
  BunnyWorld() {
    Aabb b;
    for (const vec3& p : bunny()->positions) b.grow(p);
    const float size = glm::length(b.extent());
    add(reg, bunny(), test::at(-b.center()), Kinematics::Type::Static);
    add(reg, bunny(),
        test::at(vec3(0.8f * size, 0.0f, 0.0f) - b.center(), vec3(0.7f),
                 glm::angleAxis(0.9f, glm::normalize(vec3(0.3f, 1.0f, -0.2f)))),
        Kinematics::Type::Free);
    add(reg, std::make_shared<const TriangleMesh>(
                 make_primitive(test::primitive("box", 1.0f, vec3(0.3f * size)), "test")),
        test::at(vec3(-0.7f * size, 0.1f * size, 0.2f * size)), Kinematics::Type::Hierarchical);
    update_world_transforms(reg, 1);
    layer.sync(reg);
    center = vec3(0.0f);
    half = vec3(1.2f * size, 0.5f * size, 0.5f * size);
    radius = 2.0f * size;
  }
};

// Walks on a tiny budget (every ray saved and resumed) against the native backend: the same hits
// and occlusion to the bit, every ray resumed, none cut.
void expect_resumed_walks_agree(const VulkanTracer& gpu, const NativeTracer& native,
                                const std::vector<Ray>& rays) {
  const Agreement a = compare(gpu, native, rays);
  const GpuTraceCounters c = gpu.counters();
  EXPECT_GT(a.hits, a.rays / 5);
  EXPECT_EQ(a.identical, a.rays) << a.first_difference;
  EXPECT_GT(c.resumed, rays.size()); // most rays many times over
  EXPECT_GT(c.dispatches, 10u);
  EXPECT_EQ(c.cut, 0u);
  std::vector<std::uint8_t> oa(rays.size()), ob(rays.size());
  gpu.occluded(rays, oa);
  native.occluded(rays, ob);
  EXPECT_EQ(oa, ob);
  EXPECT_GT(gpu.counters().resumed, 0u);
  EXPECT_EQ(gpu.counters().cut, 0u);
}

class VulkanTrace : public testing::TestWithParam<GpuStructure> {
protected:
  VulkanOptions options() const {
    VulkanOptions o;
    o.structure = GetParam();
    return o;
  }
};

TEST_P(VulkanTrace, RandomRaysOnTheBunnyHitBitIdenticallyToTheNativeBackend) {
  SPECULA_NEED_VULKAN(gpu, options());
  BunnyWorld w;
  NativeTracer native(8, native_like(options()));
  gpu->update(w.layer);
  native.update(w.layer);
  const Agreement a = compare(*gpu, native, random_rays(20000, w.center, w.half, w.radius, 7));
  EXPECT_GT(a.hits, a.rays / 5);
  // Same structures, same arithmetic: every hit matches to the bit.
  EXPECT_EQ(a.identical, a.rays) << a.first_difference;
  EXPECT_EQ(gpu->counters().cut, 0u);
  EXPECT_EQ(gpu->counters().rays, a.rays);
}

TEST_P(VulkanTrace, AStaticOnlySceneTracedWithoutTheTopLevelsCodeHitsBitIdentically) {
  // No dynamic instance: the tracer dispatches its pipeline with the top level compiled out.
  SPECULA_NEED_VULKAN(gpu, options());
  ecs::Registry reg;
  add(reg, bunny(), test::at(vec3(0.0f)), Kinematics::Type::Static);
  update_world_transforms(reg, 1);
  SceneLayer layer;
  layer.sync(reg);
  NativeTracer native(8, native_like(options()));
  gpu->update(layer);
  native.update(layer);
  EXPECT_FALSE(gpu->scene().has_top_level());
  Aabb b;
  for (const vec3& p : bunny()->positions) b.grow(p);
  const Agreement a = compare(*gpu, native,
                              random_rays(20000, b.center(), 0.5f * b.extent(),
                                          2.0f * glm::length(b.extent()), 13));
  EXPECT_GT(a.hits, a.rays / 5);
  EXPECT_EQ(a.identical, a.rays) << a.first_difference;
  EXPECT_EQ(gpu->counters().cut, 0u);
}

TEST_P(VulkanTrace, AStaticOnlySceneOnATinyBudgetResumesEveryRayAndChangesNoHit) {
  // The static set's own walk (trace_run_static_bvh for a BVH) saved and resumed every 3 steps.
  VulkanOptions o = options();
  o.traversal_budget = 3;
  SPECULA_NEED_VULKAN(gpu, o);
  ecs::Registry reg;
  add(reg, bunny(), test::at(vec3(0.0f)), Kinematics::Type::Static);
  update_world_transforms(reg, 1);
  SceneLayer layer;
  layer.sync(reg);
  NativeTracer native(8, native_like(o));
  gpu->update(layer);
  native.update(layer);
  EXPECT_FALSE(gpu->scene().has_top_level());
  Aabb b;
  for (const vec3& p : bunny()->positions) b.grow(p);
  expect_resumed_walks_agree(
      *gpu, native,
      random_rays(2000, b.center(), 0.5f * b.extent(), 2.0f * glm::length(b.extent()), 17));
}

TEST_P(VulkanTrace, ATinyBudgetResumesEveryRayAndChangesNoHit) {
  VulkanOptions o = options();
  o.traversal_budget = 3;
  SPECULA_NEED_VULKAN(gpu, o);
  BunnyWorld w;
  NativeTracer native(8, native_like(o));
  gpu->update(w.layer);
  native.update(w.layer);
  expect_resumed_walks_agree(*gpu, native, random_rays(2000, w.center, w.half, w.radius, 11));
}

TEST_P(VulkanTrace, RaysAtEdgesAndVerticesAndGrazingRaysHitAsTheCpuWatertightTestDoes) {
  SPECULA_NEED_VULKAN(gpu, options());
  // A closed icosphere static and the same mesh as a rotated dynamic instance: rays through its
  // vertices and edge midpoints from inside and outside, and grazing rays in the planes of its
  // triangles through their vertices.
  const auto mesh = std::make_shared<const TriangleMesh>(test::icosphere(2));
  ecs::Registry reg;
  const Transform placed = test::at(vec3(3.0f, 0.5f, -1.0f), vec3(1.3f),
                                    glm::angleAxis(0.7f, glm::normalize(vec3(1.0f, 2.0f, 3.0f))));
  add(reg, mesh, test::at(vec3(0.0f)), Kinematics::Type::Static);
  add(reg, mesh, placed, Kinematics::Type::Free);
  update_world_transforms(reg, 1);
  SceneLayer layer;
  layer.sync(reg);
  NativeTracer native(8, native_like(options()));
  gpu->update(layer);
  native.update(layer);
  std::vector<Ray> rays;
  for (const mat4& m : {mat4(1.0f), mat4(placed.parent_from_local())}) {
    const vec3 center = vec3(m[3]);
    const auto world = [&](const vec3& p) { return vec3(m * vec4(p, 1.0f)); };
    std::vector<vec3> targets;
    for (const vec3& p : mesh->positions) targets.push_back(world(p));
    for (const uvec3& t : mesh->triangles) {
      targets.push_back(world(0.5f * (mesh->positions[t.x] + mesh->positions[t.y])));
      targets.push_back(world(0.5f * (mesh->positions[t.y] + mesh->positions[t.z])));
    }
    for (const vec3& target : targets) {
      for (const vec3& origin : {center, center + vec3(0.1f, -0.2f, 0.05f), center + 5.0f * (target - center)}) {
        Ray r;
        r.origin = origin;
        r.direction = glm::normalize(target - origin);
        rays.push_back(r);
      }
    }
    for (const uvec3& t : mesh->triangles) { // grazing: along an edge, from beyond its end
      const vec3 a = world(mesh->positions[t.x]), b = world(mesh->positions[t.y]);
      Ray r;
      r.origin = a + 2.0f * (a - b);
      r.direction = glm::normalize(b - a);
      rays.push_back(r);
    }
  }
  const Agreement agreement = compare(*gpu, native, rays);
  EXPECT_EQ(agreement.identical, agreement.rays) << agreement.first_difference;
}

TEST(VulkanTraceGrid, EveryGridDensityWalksItsCellsAsTheCpuDda) {
  // Coarse grids put many triangles in a cell (long leaf lists, hits beyond the cell), fine ones
  // make the DDA take hundreds of steps: both must walk exactly as UniformGrid::traverse.
  for (const float density : {0.05f, 1.0f, 16.0f}) {
    VulkanOptions o;
    o.structure = GpuStructure::grid;
    o.grid_density = density;
    SPECULA_NEED_VULKAN(gpu, o);
    BunnyWorld w;
    NativeTracer native(8, native_like(o));
    gpu->update(w.layer);
    native.update(w.layer);
    EXPECT_EQ(gpu->scene().native().grid().header().cell_count,
              native.grid().header().cell_count);
    const Agreement a = compare(*gpu, native, random_rays(4000, w.center, w.half, w.radius, 3));
    EXPECT_EQ(a.identical, a.rays) << "density " << density << ": " << a.first_difference;
  }
}

INSTANTIATE_TEST_SUITE_P(Structures, VulkanTrace,
                         testing::Values(GpuStructure::bvh, GpuStructure::grid),
                         [](const testing::TestParamInfo<GpuStructure>& p) {
                           return std::string(p.param == GpuStructure::bvh ? "bvh" : "grid");
                         });

// ---- Updates -------------------------------------------------------------------------------------

/// A ground plane (static), a sphere moving freely and a blob whose vertices are animated, ticked by
/// the schedule on the vulkan backend; a NativeTracer follows the same layer.
struct AnimatedWorld {
  ecs::Registry reg;
  ecs::Entity ball, blob;
  NativeTracer native{8, native_like(VulkanOptions{})};
  Schedule schedule;
  AnimatedWorld() {
    test::add_mesh(reg, test::primitive("plane", 1, vec3(20, 1, 20)), test::at(vec3(0)));
    ball = test::add_mesh(reg, test::primitive("sphere", 1.0f), test::at(vec3(2, 1, 0)), Material{},
                          Kinematics::Type::Free);
    blob = test::add_mesh(reg, test::primitive("sphere", 0.5f, vec3(1), 16, 8),
                          test::at(vec3(0, 1, 4)), Material{}, Kinematics::Type::Free);
    test::add_camera(reg, vec3(0, 5, 10), vec3(0));
    RenderJob job;
    job.backend = "vulkan";
    job.settings.mode = TraceMode::Cast;
    job.image = Framebuffer(8, 8);
    prepare_rendering(reg, std::move(job));
  }
  VulkanTracer& gpu() { return dynamic_cast<VulkanTracer&>(*reg.resource<ActiveTracer>().tracer); }
  void tick(double dt) {
    schedule.tick(reg, dt);
    native.update(reg.resource<SceneLayer>());
  }
  /// Rays down onto the whole scene.
  static std::vector<Ray> rays() {
    std::vector<Ray> out;
    for (int z = -30; z <= 30; ++z)
      for (int x = -30; x <= 30; ++x) {
        Ray r;
        r.origin = vec3(0.2f * float(x), 10.0f, 0.2f * float(z));
        r.direction = glm::normalize(vec3(0.01f * float(x), -1.0f, 0.013f * float(z)));
        out.push_back(r);
      }
    return out;
  }
};

bool vulkan_available() { return try_vulkan() != nullptr; }

TEST(VulkanTraceUpdates, AnUnchangedFrameUploadsNothingAndAMoveOnlyTheTopLevel) {
  if (!vulkan_available()) GTEST_SKIP() << "no Vulkan device on this machine";
  AnimatedWorld w;
  w.tick(0.0);
  EXPECT_TRUE(w.gpu().scene().last_upload().full);
  w.tick(0.1);
  EXPECT_EQ(w.gpu().scene().last_upload().bytes, 0u);
  EXPECT_EQ(w.gpu().scene().last_upload().writes, 0u);

  w.reg.get<Transform>(w.ball).translation = vec3(-1.0f, 1.5f, 1.0f);
  w.tick(0.1);
  const GpuUploadStats& up = w.gpu().scene().last_upload();
  EXPECT_FALSE(up.full);
  // Its instance record, two top-level entries, the top level's 3 nodes and 2 indices.
  EXPECT_EQ(up.bytes, sizeof(GpuInstance) + 2 * sizeof(GpuTopEntry) + 3 * sizeof(BvhNode) +
                          2 * sizeof(std::uint32_t));
  const Agreement a = compare(w.gpu(), w.native, AnimatedWorld::rays());
  EXPECT_EQ(a.identical, a.rays) << a.first_difference;
  EXPECT_GT(a.hits, 0u);
}

TEST(VulkanTraceUpdates, ADeformedMeshIsRefittedOnTheDeviceAndHitsFollow) {
  if (!vulkan_available()) GTEST_SKIP() << "no Vulkan device on this machine";
  AnimatedWorld w;
  Animation anim;
  const auto& base = w.reg.get<Mesh>(w.blob).geometry->positions;
  std::vector<vec3> grown = base;
  for (vec3& p : grown) p = vec3(p.x * 6.0f, p.y * 2.0f, p.z * 6.0f);
  anim.vertices.times = {0.0f, 1.0f};
  anim.vertices.values = {base, grown};
  w.reg.emplace<Animation>(w.blob, anim);
  w.tick(0.0);
  const std::vector<Ray> rays = AnimatedWorld::rays();
  std::vector<Hit> before(rays.size());
  w.gpu().intersect(rays, before);
  w.tick(0.7);
  EXPECT_EQ(w.gpu().last_update().blas_refits, 1u);
  EXPECT_FALSE(w.gpu().scene().last_upload().full);
  const Agreement a = compare(w.gpu(), w.native, rays);
  EXPECT_EQ(a.identical, a.rays) << a.first_difference;
  std::vector<Hit> after(rays.size());
  w.gpu().intersect(rays, after);
  std::size_t changed = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) changed += identical(before[i], after[i]) ? 0 : 1;
  EXPECT_GT(changed, 100u); // the blob grew under many rays
}

// ---- Failure -------------------------------------------------------------------------------------

TEST(VulkanTraceFailure, ALostDeviceIsAGpuErrorFromIntersectNotACrash) {
  SPECULA_NEED_VULKAN(gpu, VulkanOptions{});
  BunnyWorld w;
  gpu->update(w.layer);
  const std::vector<Ray> rays = random_rays(64, w.center, w.half, w.radius, 5);
  std::vector<Hit> hits(rays.size());
  gpu->intersect(rays, hits);
  gpu->context().simulate_device_loss();
  try {
    gpu->intersect(rays, hits);
    FAIL() << "expected GpuError";
  } catch (const GpuError& e) {
    EXPECT_TRUE(e.device_lost()) << e.what();
  }
  std::vector<std::uint8_t> occluded(rays.size());
  EXPECT_THROW(gpu->occluded(rays, occluded), GpuError);
}

// trace.glsl walks a BVH in grouped loops (nodes up to a leaf, then the leaf), which lavapipe's
// iteration cap counts together with the outer loop's iterations: a walk far longer than the
// default budget must still be saved and resumed at each budget, never cut. 24,576 stacked
// triangles whose boxes all contain the rays' line but which the rays miss: every ray visits
// every node and tests every triangle (about 2.5 budgets' worth of steps).
TEST(VulkanTraceFailure, ABvhWalkOfSeveralBudgetsIsResumedNotCut) {
  SPECULA_NEED_VULKAN(gpu, VulkanOptions{});
  auto mesh = std::make_shared<TriangleMesh>();
  constexpr std::uint32_t kLayers = 24576;
  for (std::uint32_t i = 0; i < kLayers; ++i) {
    const float z = 0.001f * float(i);
    mesh->positions.insert(mesh->positions.end(),
                           {vec3(0.0f, 0.0f, z), vec3(1.0f, 0.0f, z), vec3(0.0f, 1.0f, z)});
    mesh->triangles.push_back(uvec3(3 * i, 3 * i + 1, 3 * i + 2));
  }
  ecs::Registry reg;
  add(reg, mesh, test::at(vec3(0.0f)), Kinematics::Type::Static);
  update_world_transforms(reg, 1);
  SceneLayer layer;
  layer.sync(reg);
  gpu->update(layer);
  NativeTracer native(8, native_like(VulkanOptions{}));
  native.update(layer);
  std::vector<Ray> rays(64);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    // Inside every box (x, y < 1), beyond every hypotenuse (x + y > 1).
    rays[i].origin = vec3(0.6f + 0.004f * float(i % 8), 0.6f + 0.004f * float(i / 8), 20.0f);
    rays[i].direction = vec3(0.0f, 0.0f, -1.0f);
  }
  std::vector<Hit> a(rays.size()), b(rays.size());
  gpu->intersect(rays, a);
  const GpuTraceCounters c = gpu->counters();
  native.intersect(rays, b);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    EXPECT_FALSE(a[i].hit()) << i;
    EXPECT_TRUE(identical(a[i], b[i])) << i;
  }
  EXPECT_EQ(c.cut, 0u);
  EXPECT_GE(c.resumed, 2 * rays.size()); // each ray saved at least twice
  EXPECT_GT(c.steps, 2 * std::uint64_t(VulkanOptions{}.traversal_budget) * rays.size());
  std::vector<std::uint8_t> occluded(rays.size(), 1);
  gpu->occluded(rays, occluded);
  EXPECT_EQ(gpu->counters().cut, 0u);
  EXPECT_EQ(occluded, std::vector<std::uint8_t>(rays.size(), 0));
}

TEST(VulkanTraceFailure, AWalkTheDriverCutsOffIsReportedAsCutNotAsAWrongHit) {
  // Lavapipe's silent loop cap (PLATFORM-NOTES): a budget past it (measured: 32,768 steps) lets
  // the driver end the walk. The kernel must leave such rays pending and the tracer say so.
  VulkanOptions o;
  o.structure = GpuStructure::grid;
  o.grid_density = 1e-6f; // one cell: every ray tests every triangle, one step each
  o.traversal_budget = 40000;
  SPECULA_NEED_VULKAN(gpu, o);
  if (!gpu->context().info().is_cpu()) GTEST_SKIP() << "the loop cap is lavapipe's";
  ecs::Registry reg;
  add(reg, std::make_shared<const TriangleMesh>(test::icosphere(6)), test::at(vec3(0.0f)),
      Kinematics::Type::Static); // 81,920 triangles
  update_world_transforms(reg, 1);
  SceneLayer layer;
  layer.sync(reg);
  gpu->update(layer);
  std::vector<Ray> rays(16);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    rays[i].origin = vec3(0.01f * float(i), 0.0f, 5.0f);
    rays[i].direction = vec3(0.0f, 0.0f, -1.0f);
  }
  std::vector<Hit> hits(rays.size());
  EXPECT_THROW(gpu->intersect(rays, hits), Error);
  EXPECT_EQ(gpu->counters().cut, rays.size());
}

} // namespace
} // namespace specula::gpu
