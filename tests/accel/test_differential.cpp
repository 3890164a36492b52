// Differential test: every native structure (kd-tree, BVH and grid for the static set; the
// two-level structure with per-mesh BVHs for dynamic instances) against Embree on the same scenes,
// ≥ 1M seeded random rays per scene and stage (coherent: from one eye point; incoherent: random
// origins and directions), including after refits and after selective restructuring of a deforming
// mesh. Every ray must find the same closest primitive (or another at an equal distance: a tie on a
// shared edge) at a distance within 1e-5 relative; any-hit queries must agree with closest hits.
// Sanitizer and debug builds shoot 1/16 of the rays (the optimised CI build shoots them all).

#include "scene_builder.h"
#include "specula/accel/native/native_tracer.h"
#include "specula/render/tracer_factory.h"

#include <gtest/gtest.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <random>
#include <string>
#include <vector>

namespace specula {
namespace {

#ifdef NDEBUG
constexpr std::size_t kRaysPerStage = std::size_t(1) << 20;
#else
constexpr std::size_t kRaysPerStage = std::size_t(1) << 16;
#endif

bool has_embree() { return backend_info("embree").available; }

/// The world bounds of every live instance.
Aabb world_bounds(const SceneTables& tables) {
  Aabb bounds;
  for (std::uint32_t slot = 0; slot < tables.instances.size(); ++slot)
    if (tables.live(slot)) {
      bounds.grow(tables.instances[slot].world_bounds_min);
      bounds.grow(tables.instances[slot].world_bounds_max);
    }
  return bounds;
}

/// Half coherent (from `eye` through a cone around the scene centre), half incoherent.
std::vector<Ray> make_rays(const Aabb& bounds, const vec3& eye, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  const vec3 lo = bounds.min - 0.1f * bounds.extent(), hi = bounds.max + 0.1f * bounds.extent();
  const auto point = [&] { return lo + vec3(unit(rng), unit(rng), unit(rng)) * (hi - lo); };
  std::vector<Ray> rays(kRaysPerStage);
  for (std::size_t i = 0; i < rays.size(); ++i) {
    Ray& r = rays[i];
    if (i % 2 == 0) {
      r.origin = eye;
      r.direction = glm::normalize(point() - eye);
    } else {
      r.origin = point();
      vec3 d(0.0f);
      while (glm::length(d) < 1e-3f) d = vec3(unit(rng), unit(rng), unit(rng)) * 2.0f - 1.0f;
      r.direction = glm::normalize(d);
    }
  }
  return rays;
}

/// Every triangle of every live instance tested (the arbiter when the two tracers disagree).
Hit brute_force(const SceneTables& t, const Ray& ray) {
  Hit best;
  for (std::uint32_t slot = 0; slot < t.instances.size(); ++slot) {
    if (!t.live(slot)) continue;
    const gpu::GpuInstance& inst = t.instances[slot];
    const gpu::GpuMesh& m = t.meshes[inst.mesh];
    const mat4 object_from_world = glm::inverse(inst.world_from_object);
    const accel::TriangleView view{t.positions.data() + m.first_vertex,
                                   t.triangles.data() + m.first_triangle, m.triangle_count};
    const accel::PreparedRay r = accel::PreparedRay::make(
        vec3(object_from_world * vec4(ray.origin, 1.0f)), mat3(object_from_world) * ray.direction,
        ray.tnear, std::min(ray.tfar, best.t));
    const accel::TriangleHit h = accel::brute_force_closest(view, r);
    if (h.hit() && h.t < best.t) {
      best.t = h.t;
      best.instance = slot;
      best.primitive = h.prim;
      best.uv = vec2(h.u, h.v);
    }
  }
  return best;
}

struct Comparison {
  std::size_t rays = 0, hits = 0, ties = 0, grazes = 0, mismatches = 0, occlusion_mismatches = 0;
  std::string first_mismatch;
};

/// |cos θ| between a ray and the world-space normal of the triangle it hit.
float cos_to_normal(const SceneTables& tables, const Hit& h, const vec3& direction) {
  const gpu::GpuInstance& inst = tables.instances[h.instance];
  const vec3 n = mat3(vec3(inst.normal_from_object[0]), vec3(inst.normal_from_object[1]),
                      vec3(inst.normal_from_object[2])) * h.object_normal;
  return std::abs(glm::dot(glm::normalize(n), direction));
}

/// A ray that grazes a triangle — within 1e-4 of an edge in barycentrics (Embree rounds an
/// instance's transform differently: 6e-5 seen at t = 16 through a scaled, rotated instance), or
/// within 1e-2 of its plane in angle (a silhouette): either tracer may rightly call it a hit or a
/// miss.
bool grazes(const SceneTables& tables, const Hit& h, const vec3& direction) {
  constexpr float e = 1e-4f;
  return h.uv.x < e || h.uv.y < e || h.uv.x + h.uv.y > 1.0f - e ||
         cos_to_normal(tables, h, direction) < 1e-2f;
}

Comparison compare(const Tracer& reference, const Tracer& tested, const std::vector<Ray>& rays,
                   const SceneTables& tables) {
  std::vector<Hit> a(rays.size()), b(rays.size());
  std::vector<std::uint8_t> occ(rays.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rays.size(), 4096), [&](const auto& range) {
    const std::span<const Ray> chunk(rays.data() + range.begin(), range.size());
    reference.intersect(chunk, std::span<Hit>(a.data() + range.begin(), range.size()));
    tested.intersect(chunk, std::span<Hit>(b.data() + range.begin(), range.size()));
    tested.occluded(chunk, std::span<std::uint8_t>(occ.data() + range.begin(), range.size()));
  });
  Comparison c;
  c.rays = rays.size();
  for (std::size_t i = 0; i < rays.size(); ++i) {
    const Hit& ha = a[i];
    const Hit& hb = b[i];
    if (hb.hit() != (occ[i] != 0)) ++c.occlusion_mismatches;
    bool ok;
    if (!ha.hit() || !hb.hit()) {
      ok = ha.hit() == hb.hit();
      if (!ok && grazes(tables, ha.hit() ? ha : hb, rays[i].direction)) {
        ++c.grazes;
        ok = true;
      }
    } else {
      ++c.hits;
      // Relative to the distance, or to the coordinates' magnitude for a hit very close to its
      // origin (a t of 1e-3 from an origin at 8 carries 8·2⁻²⁴ of absolute rounding).
      const vec3 o = glm::abs(rays[i].origin);
      const float scale = std::max({ha.t, hb.t, o.x, o.y, o.z});
      bool close = std::abs(ha.t - hb.t) <= 1e-5f * scale;
      const bool same = ha.instance == hb.instance && ha.primitive == hb.primitive;
      if (!close && same) {
        // The same triangle at a grazing angle: t is ill-conditioned there (each tracer rounds
        // the instance transform its own way), so the tolerance grows with 1 / |cos θ|.
        const float cos_theta = cos_to_normal(tables, ha, rays[i].direction);
        close = std::abs(ha.t - hb.t) <= 1e-5f * scale / std::max(cos_theta, 1e-2f);
      }
      ok = close;
      // One tracer found a hit the other passed: fine only where the ray grazes the edge of the
      // nearer triangle (a silhouette), within float rounding of either test.
      if (!close && grazes(tables, ha.t < hb.t ? ha : hb, rays[i].direction)) {
        ++c.grazes;
        ok = true;
      }
      if (close && !same) {
        ++c.ties;
      }
    }
    if (!ok) {
      if (c.mismatches == 0) {
        const Hit bf = brute_force(tables, rays[i]);
        c.first_mismatch = "ray " + std::to_string(i) + ": brute force t=" + std::to_string(bf.t) +
                           " inst=" + std::to_string(bf.instance) + " prim=" +
                           std::to_string(bf.primitive) + ", reference t=" + std::to_string(ha.t) +
                           " inst=" + std::to_string(ha.instance) + " prim=" +
                           std::to_string(ha.primitive) + ", tested t=" + std::to_string(hb.t) +
                           " inst=" + std::to_string(hb.instance) + " prim=" +
                           std::to_string(hb.primitive) + " (reference uv " +
                           std::to_string(ha.uv.x) + " " + std::to_string(ha.uv.y) + ")";
      }
      ++c.mismatches;
    }
  }
  return c;
}

void expect_agreement(const Comparison& c, const std::string& what) {
  SCOPED_TRACE(what);
  EXPECT_GE(c.rays, kRaysPerStage);
  EXPECT_GT(c.hits, c.rays / 8) << "the scene must be hit, not mostly missed";
  EXPECT_EQ(c.mismatches, 0u) << c.first_mismatch;
  EXPECT_EQ(c.occlusion_mismatches, 0u);
  // Ties are rays through shared edges, grazes rays along silhouette edges: a handful at most
  // among random rays (at most 1 in 10,000 of either; the scrambled blob's slivers graze most).
  EXPECT_LE(c.ties * 10000, c.rays);
  EXPECT_LE(c.grazes * 10000, c.rays);
}

/// Static scene: a finely tessellated sphere, boxes, a plane and a random soup of big and small
/// triangles (sliver and zero-area ones among them).
void build_static_scene(ecs::Registry& reg) {
  test::add_mesh(reg, test::primitive("sphere", 1.0f, vec3(1), 256, 128), test::at(vec3(0, 1, 0)));
  test::add_mesh(reg, test::primitive("plane", 1, vec3(30, 1, 30)), test::at(vec3(0)));
  for (int i = 0; i < 6; ++i)
    test::add_mesh(reg, test::primitive("box", 1, vec3(1.0f + float(i) * 0.3f, 2.0f, 0.7f)),
                   // Clear of the ground: coplanar faces would make every hit there a tie.
                   test::at(vec3(-6.0f + 2.2f * float(i), 1.05f, -4.0f), vec3(1.0f),
                            glm::angleAxis(0.3f * float(i), vec3(0, 1, 0))));
  std::mt19937 rng(99);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  auto soup = std::make_shared<TriangleMesh>();
  for (int t = 0; t < 20000; ++t) {
    const vec3 c(u(rng) * 8.0f, 2.0f + u(rng) * 2.0f, 4.0f + u(rng) * 3.0f);
    const float s = t % 50 == 0 ? 2.0f : 0.05f;
    const auto base = std::uint32_t(soup->positions.size());
    const vec3 a = c + s * vec3(u(rng), u(rng), u(rng));
    const vec3 b = t % 97 == 0 ? a : c + s * vec3(u(rng), u(rng), u(rng)); // zero-area
    const vec3 d = t % 89 == 0 ? a + 1e-6f * (b - a) : c + s * vec3(u(rng), u(rng), u(rng));
    soup->positions.insert(soup->positions.end(), {a, b, d});
    soup->triangles.emplace_back(base, base + 1, base + 2);
  }
  soup->compute_vertex_normals();
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e, test::at(vec3(0)));
  reg.emplace<Mesh>(e, Mesh{soup, {}, {}, 0});
  reg.emplace<Kinematics>(e, Kinematics{Kinematics::Type::Static});
}

TEST(Differential, StaticStructuresAgreeWithEmbree) {
  if (!has_embree()) GTEST_SKIP() << "no Embree in this build: nothing to compare against";
  ecs::Registry reg;
  build_static_scene(reg);
  const test::TracedWorld reference(reg, "embree");
  const std::vector<Ray> rays = make_rays(world_bounds(reference.tables()), vec3(3, 6, 14), 1234);
  for (const char* backend : {"native", "native-bvh", "native-grid"}) {
    const test::TracedWorld tested(reg, backend);
    expect_agreement(compare(*reference.tracer, *tested.tracer, rays, reference.tables()), backend);
  }
  // The BVH's 4-wide collapse for single rays (NativeOptions::wide_bvh), both tests.
  for (const auto test : {accel::TriangleTest::watertight, accel::TriangleTest::moller_trumbore}) {
    NativeOptions options;
    options.static_structure = StaticStructure::bvh;
    options.wide_bvh = true;
    options.triangle_test = test;
    NativeTracer tested(1, options);
    tested.update(reference.layer);
    expect_agreement(compare(*reference.tracer, tested, rays, reference.tables()),
                     test == accel::TriangleTest::watertight ? "4-wide BVH" : "4-wide BVH (MT)");
  }
}

TEST(Differential, TheMollerTrumboreOptionAgreesWithEmbreeToo) {
  if (!has_embree()) GTEST_SKIP() << "no Embree in this build: nothing to compare against";
  ecs::Registry reg;
  build_static_scene(reg);
  const test::TracedWorld reference(reg, "embree");
  const std::vector<Ray> rays = make_rays(world_bounds(reference.tables()), vec3(-5, 3, 12), 4321);
  for (const StaticStructure s : {StaticStructure::kdtree, StaticStructure::bvh}) {
    NativeOptions options;
    options.static_structure = s;
    options.triangle_test = accel::TriangleTest::moller_trumbore;
    NativeTracer tested(1, options);
    tested.update(reference.layer);
    expect_agreement(compare(*reference.tracer, tested, rays, reference.tables()),
                     std::string(tested.name()) + " (MT)");
  }
}

/// Two levels: a static floor and pillar, rigid free and hierarchical instances (rotated, scaled,
/// sharing one mesh), and a deforming mesh animated between its rest pose, a mild wave and a large
/// scramble that forces restructuring.
struct DynamicScene {
  ecs::Registry reg;
  ecs::Entity blob;
  DynamicScene() {
    test::add_mesh(reg, test::primitive("plane", 1, vec3(20, 1, 20)), test::at(vec3(0)));
    test::add_mesh(reg, test::primitive("box", 1, vec3(1, 4, 1)), test::at(vec3(-3, 2, 0)));
    std::mt19937 rng(5);
    std::uniform_real_distribution<float> u(-1.0f, 1.0f);
    const ecs::Entity first = test::add_mesh(reg, test::primitive("sphere", 0.7f, vec3(1), 48, 24),
                                             test::at(vec3(2, 1, 0)), Material{}, Kinematics::Type::Free);
    for (int i = 0; i < 24; ++i) {
      const ecs::Entity e = reg.create();
      const vec3 axis = glm::normalize(vec3(u(rng), u(rng), u(rng)) + vec3(0, 0, 0.01f));
      reg.emplace<Transform>(e, test::at(vec3(u(rng) * 8.0f, 1.0f + std::abs(u(rng)) * 3.0f, u(rng) * 8.0f),
                                         vec3(0.5f + std::abs(u(rng)), 0.5f + std::abs(u(rng)), 1.0f),
                                         glm::angleAxis(u(rng) * 3.0f, axis)));
      reg.emplace<Mesh>(e, reg.get<Mesh>(first));
      reg.emplace<Kinematics>(e, Kinematics{i % 2 ? Kinematics::Type::Hierarchical : Kinematics::Type::Free});
    }
    test::add_camera(reg, vec3(0, 5, 12), vec3(0));
    blob = test::add_mesh(reg, test::primitive("sphere", 1.5f, vec3(1), 96, 48), test::at(vec3(0, 2, 4)),
                          Material{}, Kinematics::Type::Free);
    const auto& base = reg.get<Mesh>(blob).geometry->positions;
    std::vector<vec3> wave = base, scramble = base;
    for (vec3& p : wave) p.y += 0.3f * std::sin(4.0f * p.x) * std::cos(3.0f * p.z);
    for (vec3& p : scramble) p = vec3(u(rng), u(rng), u(rng)) * 2.5f;
    Animation anim;
    anim.vertices.times = {0.0f, 1.0f, 2.0f};
    anim.vertices.values = {base, wave, scramble};
    reg.emplace<Animation>(blob, anim);
  }
};

TEST(Differential, TwoLevelStructureAgreesWithEmbreeThroughRefitsAndRestructuring) {
  if (!has_embree()) GTEST_SKIP() << "no Embree in this build: nothing to compare against";
  for (const char* backend : {"native", "native-bvh", "native-grid"}) {
    DynamicScene scene;
    RenderJob job;
    job.backend = "embree";
    job.settings.mode = TraceMode::Cast;
    job.image = Framebuffer(8, 8);
    prepare_rendering(scene.reg, std::move(job));
    Schedule schedule;
    // The tested backend follows the same layer as the reference (the layer is the registry's).
    auto tested = make_tracer(backend, 1);
    std::uint32_t restructures = 0, refits = 0;
    std::uint32_t seed = 77;
    double now = 0.0;
    for (const double time : {0.0, 0.5, 1.0, 1.6, 2.0}) {
      schedule.tick(scene.reg, time - now);
      now = time;
      const SceneLayer& layer = scene.reg.resource<SceneLayer>();
      tested->update(layer);
      refits += tested->last_update().blas_refits;
      restructures += tested->last_update().blas_restructures;
      const std::vector<Ray> rays = make_rays(world_bounds(layer.tables()), vec3(1, 7, 13), seed++);
      expect_agreement(compare(*scene.reg.resource<ActiveTracer>().tracer, *tested, rays,
                               layer.tables()),
                       std::string(backend) + " at t=" + std::to_string(time));
    }
    EXPECT_GE(refits, 4u) << backend;
    EXPECT_GE(restructures, 1u) << backend << ": the scramble must degrade the blob's BVH";
  }
}

} // namespace
} // namespace specula
