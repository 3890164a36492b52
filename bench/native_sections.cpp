// specula_bench sections on Specula's own structures (engine/accel), each against Embree where
// Embree has an equivalent, measured in the same run with interleaved repetitions:
//   build   kd-tree and BVH build time against n (1k … 1M triangles), fitted exponents
//   refit   BVH refit and selective restructuring of a 100k-triangle deforming mesh, one core
//   native  Mrays/s of primary, shadow and reflection rays: native single rays and packets
//           against Embree single rays and packets of the same width, same rays
//   paper   the real-time ray tracer paper's table: BVH only against kd-tree + BVH, on two
//           animated scenes, diffuse / + shadows / + reflection & refraction / all

#include "bench_common.h"
#include "specula/accel/bvh/bvh.h"
#include "specula/accel/embree/embree_tracer.h"
#include "specula/accel/kdtree/kdtree.h"
#include "specula/accel/native/native_tracer.h"
#include "specula/geometry/primitives.h"
#include "specula/render/render_job.h"
#include "specula/render/scene_layer.h"
#include "specula/scene/components.h"
#include "specula/scene/hierarchy.h"
#include "specula/systems/schedule.h"
#include "specula/trace/optics.h"
#include "specula/trace/render_frame.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <string>
#include <vector>

namespace specula::bench {
namespace {

/// A UV sphere of about n triangles (segments s, rings s/2: 2·s·(s/2) − 2s ≈ s²).
TriangleMesh sphere_of(std::uint32_t n) {
  MeshSource s;
  s.kind = MeshSource::Kind::Primitive;
  s.primitive = "sphere";
  s.segments = std::max(8u, std::uint32_t(std::lround(std::sqrt(double(n)))));
  s.rings = std::max(4u, s.segments / 2);
  return make_primitive(s, "bench");
}

accel::TriangleView view_of(const TriangleMesh& m) {
  return {m.positions.data(), m.triangles.data(), std::uint32_t(m.triangles.size())};
}

/// Least-squares slope of log(y) against log(x).
double fitted_exponent(const std::vector<double>& x, const std::vector<double>& y) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  const auto n = double(x.size());
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double lx = std::log(x[i]), ly = std::log(y[i]);
    sx += lx;
    sy += ly;
    sxx += lx * lx;
    sxy += lx * ly;
  }
  return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

template <typename F>
double in_arena(std::uint32_t threads, F&& f) {
  tbb::task_arena arena{static_cast<int>(threads)};
  double ms = 0.0;
  arena.execute([&] { ms = time_ms(f); });
  return ms;
}

} // namespace

void section_build(const Options& o) {
  std::printf("\n### Build time against n (UV spheres and the Loop-subdivided bunny; median of %d)\n\n",
              o.repetitions);
  std::printf("| mesh | triangles | kd-tree 1 core (ms) | kd-tree %u cores (ms) | kd-tree Mtri/s per "
              "core | BVH 1 core (ms) | BVH Mtri/s | Embree high quality, %u cores (ms) |\n",
              o.threads, o.threads);
  std::printf("|---|---:|---:|---:|---:|---:|---:|---:|\n");
  std::vector<std::pair<std::string, TriangleMesh>> meshes;
  for (std::uint32_t n = 1024; n <= o.max_build_triangles; n *= 4)
    meshes.emplace_back("sphere", sphere_of(n));
  const TriangleMesh bunny = load_bunny(o);
  for (int level = 0; level <= 4; ++level) {
    if (bunny.triangle_count() << (2 * level) > o.max_build_triangles) break;
    meshes.emplace_back("bunny ×" + std::to_string(level), subdivided(bunny, level));
  }
  std::vector<double> ns, kd_ms, bvh_ms;
  for (const auto& [name, mesh] : meshes) {
    const accel::TriangleView view = view_of(mesh);
    std::vector<double> kd1, kd2, bvh1, emb;
    Scene scene = mesh_scene(mesh, 16);
    SceneLayer layer;
    layer.sync(scene.registry);
    for (int r = 0; r < o.repetitions; ++r) {
      accel::KdTree kd;
      kd1.push_back(in_arena(1, [&] { kd.build(view); }));
      kd2.push_back(in_arena(o.threads, [&] { kd.build(view); }));
      accel::Bvh bvh;
      bvh1.push_back(in_arena(1, [&] { bvh.build(view); }));
      EmbreeTracer embree;
      emb.push_back(in_arena(o.threads, [&] { embree.update(layer); }));
    }
    const double n = double(mesh.triangle_count());
    const double k1 = median(kd1), k2 = median(kd2), b1 = median(bvh1);
    if (name == "sphere") {
      ns.push_back(n);
      kd_ms.push_back(k1);
      bvh_ms.push_back(b1);
    }
    std::printf("| %s | %zu | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f |\n", name.c_str(),
                mesh.triangle_count(), k1, k2, n / (k1 * 1e3), b1, n / (b1 * 1e3), median(emb));
    std::fflush(stdout);
  }
  if (ns.size() >= 3) {
    // n log n over the same range has a log-log slope of 1 + 1/ln(n̄) (≈ 1.08 over 1k…1M).
    std::vector<double> nlogn;
    for (const double n : ns) nlogn.push_back(n * std::log2(n));
    std::printf("\nFitted exponents over the spheres (time ∝ n^k): kd-tree k = %.3f, BVH k = %.3f; "
                "n·log n itself gives k = %.3f over this range, n·log² n gives %.3f.\n",
                fitted_exponent(ns, kd_ms), fitted_exponent(ns, bvh_ms),
                fitted_exponent(ns, nlogn), [&] {
                  std::vector<double> v;
                  for (const double n : ns) v.push_back(n * std::log2(n) * std::log2(n));
                  return fitted_exponent(ns, v);
                }());
  }
}

void section_refit(const Options& o) {
  const TriangleMesh base = sphere_of(100000);
  TriangleMesh mesh = base;
  const accel::TriangleView view = view_of(mesh);
  accel::Bvh bvh;
  in_arena(1, [&] { bvh.build(view); });
  std::vector<double> refit_ms, restructure_ms;
  std::uint32_t rebuilt = 0;
  float sah_before = 0, sah_after = 0;
  for (int r = 0; r < std::max(o.repetitions, 5); ++r) {
    // A travelling wave, then a scramble of one cap every other repetition (forces restructuring).
    const float phase = 0.7f * float(r);
    for (std::size_t i = 0; i < mesh.positions.size(); ++i) {
      const vec3& p = base.positions[i];
      mesh.positions[i] = p * (1.0f + 0.2f * std::sin(6.0f * p.y + phase));
      if (r % 2 == 1 && p.y > 0.8f) mesh.positions[i] += vec3(0.0f, 2.0f * std::sin(40.0f * p.x), 0.0f);
    }
    refit_ms.push_back(in_arena(1, [&] { bvh.refit(view); }));
    accel::RestructureStats rs;
    restructure_ms.push_back(in_arena(1, [&] { rs = bvh.restructure(view, 1.3f); }));
    rebuilt += rs.subtrees_rebuilt;
    sah_before = rs.sah_before;
    sah_after = rs.sah_after;
  }
  std::printf("\n### BVH refit and selective restructuring, %zu triangles, one core\n\n",
              mesh.triangle_count());
  std::printf("| refit (ms, median) | restructure check + rebuilds (ms, median) | subtrees rebuilt "
              "(all repetitions) | SAH before / after the last restructure |\n|---:|---:|---:|---:|\n");
  std::printf("| %.3f | %.3f | %u | %.1f / %.1f |\n", median(refit_ms), median(restructure_ms),
              rebuilt, double(sah_before), double(sah_after));
}

namespace {

/// Rays of one kind for the secondary-ray comparison, made from Embree's primary hits.
struct SecondaryRays {
  std::vector<Ray> shadow, reflection;
};

SecondaryRays make_secondary(const Tracer& reference, const SceneLayer& layer, const Camera& camera,
                             std::uint32_t size, const vec3& light) {
  const CameraRays cam(camera, size, size);
  SecondaryRays out;
  std::vector<Ray> primary;
  for (std::uint32_t y = 0; y < size; ++y)
    for (std::uint32_t x = 0; x < size; ++x) primary.push_back(cam.ray(x, y));
  std::vector<Hit> hits(primary.size());
  reference.intersect(primary, hits);
  const SceneTables& t = layer.tables();
  for (std::size_t i = 0; i < primary.size(); ++i) {
    if (!hits[i].hit()) continue;
    const Hit& h = hits[i];
    const gpu::GpuInstance& inst = t.instances[h.instance];
    vec3 n = glm::normalize(mat3(inst.normal_from_object[0], inst.normal_from_object[1],
                                 inst.normal_from_object[2]) * h.object_normal);
    if (glm::dot(n, primary[i].direction) > 0) n = -n;
    const vec3 p = primary[i].origin + h.t * primary[i].direction;
    const vec3 origin = p + n * (1e-4f * (1.0f + glm::length(p)));
    Ray s;
    s.origin = origin;
    s.direction = glm::normalize(light - origin);
    s.tfar = glm::length(light - origin);
    out.shadow.push_back(s);
    Ray r;
    r.origin = origin;
    r.direction = reflect_direction(primary[i].direction, n);
    out.reflection.push_back(r);
  }
  return out;
}

double batch_ms(std::uint32_t threads, const Tracer& tracer, const std::vector<Ray>& rays,
                bool shadow) {
  tbb::task_arena arena{static_cast<int>(threads)};
  double ms = 0.0;
  arena.execute([&] {
    ms = time_ms([&] {
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rays.size(), 1024), [&](const auto& r) {
        const std::span<const Ray> chunk(rays.data() + r.begin(), r.size());
        if (shadow) {
          std::vector<std::uint8_t> blocked(r.size());
          tracer.occluded(chunk, blocked);
        } else {
          std::vector<Hit> hits(r.size());
          tracer.intersect(chunk, hits);
        }
      });
    });
  });
  return ms;
}

} // namespace

void section_native(const Options& o) {
  const TriangleMesh bunny = load_bunny(o);
  for (const int level : {0, std::min(2, o.subdivisions)}) {
    const TriangleMesh mesh = subdivided(bunny, level);
    Scene scene = mesh_scene(mesh, o.size);
    // A ground plane below the bunny, so shadow and reflection rays have something to find.
    {
      ecs::Registry& reg = scene.registry;
      Aabb b;
      for (const vec3& p : mesh.positions) b.grow(p);
      MeshSource plane;
      plane.kind = MeshSource::Kind::Primitive;
      plane.primitive = "plane";
      plane.size = vec3(glm::length(b.extent()) * 4.0f, 1.0f, glm::length(b.extent()) * 4.0f);
      const ecs::Entity e = reg.create();
      Transform t;
      t.translation = vec3(b.center().x, b.min.y, b.center().z);
      reg.emplace<Transform>(e, t);
      reg.emplace<Mesh>(e, Mesh{std::make_shared<const TriangleMesh>(make_primitive(plane, "bench")), plane, {}, 0});
      reg.emplace<Material>(e);
      reg.emplace<Kinematics>(e);
      update_world_transforms(reg, 1);
    }
    SceneLayer layer;
    layer.sync(scene.registry);
    EmbreeTracer embree;
    embree.update(layer);
    NativeTracer native;
    native.update(layer);
    NativeOptions bvh_options;
    bvh_options.static_structure = StaticStructure::bvh;
    NativeTracer native_bvh(8, bvh_options);
    native_bvh.update(layer);
    // native-bvh traces single rays through the BVH's 4-wide collapse; the same tree without it
    // (packets use the binary tree in both) shows what the wide nodes buy, in the same run.
    NativeOptions binary_options = bvh_options;
    binary_options.wide_bvh = false;
    NativeTracer native_binary(8, binary_options);
    native_binary.update(layer);
    const Camera camera = *active_camera(scene.registry);
    TraceSettings settings;
    settings.mode = TraceMode::Cast;
    settings.threads = o.threads;
    const std::uint64_t rays = std::uint64_t(o.size) * o.size;
    std::printf("\n### Native against Embree: bunny ×%d + ground (%zu triangles), %ux%u, %u threads\n\n",
                level, mesh.triangle_count() + 2, o.size, o.size, o.threads);
    std::printf("Primary rays (generated, traced and resolved to instances by each tracer's "
                "intersect_camera):\n\n");
    std::printf("| packet width | Embree (Mrays/s) | native kd-tree (Mrays/s) | kd-tree / Embree | "
                "native BVH (Mrays/s) | BVH / Embree |\n|---:|---:|---:|---:|---:|---:|\n");
    for (const std::uint32_t w : {1u, 4u, 8u}) {
      embree.set_packet_width(w);
      native.set_packet_width(w);
      native_bvh.set_packet_width(w);
      std::vector<double> e_ms, n_ms, b_ms;
      (void)trace_primary_frame(embree, camera, o.size, o.size, settings);
      (void)trace_primary_frame(native, camera, o.size, o.size, settings);
      (void)trace_primary_frame(native_bvh, camera, o.size, o.size, settings);
      for (int r = 0; r < o.repetitions; ++r) {
        e_ms.push_back(time_ms([&] { (void)trace_primary_frame(embree, camera, o.size, o.size, settings); }));
        n_ms.push_back(time_ms([&] { (void)trace_primary_frame(native, camera, o.size, o.size, settings); }));
        b_ms.push_back(time_ms([&] { (void)trace_primary_frame(native_bvh, camera, o.size, o.size, settings); }));
      }
      const double e = mrays(rays, median(e_ms)), n = mrays(rays, median(n_ms)),
                   b = mrays(rays, median(b_ms));
      std::printf("| %u | %.2f | %.2f | %.2f | %.2f | %.2f |\n", w, e, n, n / e, b, b / e);
      std::fflush(stdout);
    }
    Aabb b;
    for (const vec3& p : mesh.positions) b.grow(p);
    const vec3 light = b.center() + vec3(0.3f, 2.0f, 0.4f) * glm::length(b.extent());
    const SecondaryRays sec = make_secondary(embree, layer, camera, o.size, light);
    std::printf("\nSecondary rays from the primary hits (batches of rays through each tracer's "
                "occluded/intersect: Embree's rtcOccluded1M/rtcIntersect1M, which trace a batch "
                "as packets of its SIMD width; the native kd-tree takes both kinds of batch as "
                "packets of 8 too (4 without AVX2), the 4-wide BVH its occlusion batches; the "
                "binary BVH column and the wide BVH's reflection rays one ray at a time):\n\n");
    std::printf("| rays | count | Embree (Mrays/s) | native kd-tree (Mrays/s) | kd-tree / Embree | "
                "native BVH, 4-wide (Mrays/s) | BVH / Embree | binary BVH (Mrays/s) | binary / "
                "Embree |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for (const bool shadow : {true, false}) {
      const std::vector<Ray>& rs = shadow ? sec.shadow : sec.reflection;
      std::vector<double> e_ms, n_ms, b_ms, bb_ms;
      (void)batch_ms(o.threads, embree, rs, shadow);
      (void)batch_ms(o.threads, native, rs, shadow);
      (void)batch_ms(o.threads, native_bvh, rs, shadow);
      (void)batch_ms(o.threads, native_binary, rs, shadow);
      for (int r = 0; r < o.repetitions; ++r) {
        e_ms.push_back(batch_ms(o.threads, embree, rs, shadow));
        n_ms.push_back(batch_ms(o.threads, native, rs, shadow));
        b_ms.push_back(batch_ms(o.threads, native_bvh, rs, shadow));
        bb_ms.push_back(batch_ms(o.threads, native_binary, rs, shadow));
      }
      const double e = mrays(rs.size(), median(e_ms)), n = mrays(rs.size(), median(n_ms)),
                   bv = mrays(rs.size(), median(b_ms)), bb = mrays(rs.size(), median(bb_ms));
      std::printf("| %s | %zu | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f |\n",
                  shadow ? "shadow" : "reflection", rs.size(), e, n, n / e, bv, bv / e, bb, bb / e);
      std::fflush(stdout);
    }
  }
}

namespace {

/// The paper's animated scenes, built in code: rigid objects moving every frame over a static set.
///   - "orbits": a static ground and the bunny; 12 reflective spheres (one glass) orbiting on free
///     kinematics and a three-part hierarchical arm swinging;
///   - "deforming": a static room of boxes and the bunny; a 9k-triangle blob deforming every frame
///     (refit, restructuring) and two mirror spheres bobbing.
Scene paper_scene(const Options& o, bool deforming) {
  Scene scene;
  ecs::Registry& reg = scene.registry;
  const auto add = [&](const TriangleMesh& mesh, const Transform& t, const Material& m,
                       Kinematics::Type k) {
    const ecs::Entity e = reg.create();
    reg.emplace<Transform>(e, t);
    reg.emplace<Mesh>(e, Mesh{std::make_shared<const TriangleMesh>(mesh), {}, {}, 0});
    reg.emplace<Material>(e, m);
    reg.emplace<Kinematics>(e, Kinematics{k});
    return e;
  };
  const auto prim = [](const char* name, vec3 size, std::uint32_t seg = 32) {
    MeshSource s;
    s.kind = MeshSource::Kind::Primitive;
    s.primitive = name;
    s.size = size;
    s.segments = seg;
    s.rings = seg / 2;
    return make_primitive(s, "bench");
  };
  const auto at = [](vec3 p, vec3 s = vec3(1)) {
    Transform t;
    t.translation = p;
    t.scale = s;
    return t;
  };
  Material matte;
  Material mirror;
  mirror.reflectivity = 0.8f;
  Material glass;
  glass.transmission = 0.9f;
  glass.reflectivity = 0.05f;
  add(prim("plane", vec3(30, 1, 30)), at(vec3(0)), matte, Kinematics::Type::Static);
  TriangleMesh bunny = subdivided(load_bunny(o), std::min(2, o.subdivisions));
  Aabb bb;
  for (const vec3& p : bunny.positions) bb.grow(p);
  const float scale = 4.0f / bb.extent().y;
  // Standing on the ground at the origin, 4 units tall.
  add(bunny, at(vec3(-bb.center().x, -bb.min.y, -bb.center().z) * scale, vec3(scale)), matte,
      Kinematics::Type::Static);
  if (!deforming) {
    for (int i = 0; i < 12; ++i) {
      const float a = 6.2831853f * float(i) / 12.0f;
      Animation anim;
      anim.translation.times = {0.0f, 1.0f, 2.0f};
      const vec3 c(6.0f * std::cos(a), 1.0f, 6.0f * std::sin(a));
      const vec3 d(6.0f * std::cos(a + 0.5f), 1.5f, 6.0f * std::sin(a + 0.5f));
      anim.translation.values = {c, d, c};
      const ecs::Entity e = add(prim("sphere", vec3(1), 48), at(c), i == 0 ? glass : mirror,
                                Kinematics::Type::Free);
      reg.emplace<Animation>(e, anim);
    }
    // A swinging three-part arm: each part a child of the previous one.
    ecs::Entity parent = ecs::null_entity;
    for (int k = 0; k < 3; ++k) {
      const ecs::Entity e = add(prim("box", vec3(0.4f, 2.0f, 0.4f)), at(k == 0 ? vec3(-5, 1, -5) : vec3(0, 2, 0)),
                                mirror, Kinematics::Type::Hierarchical);
      Animation anim;
      anim.rotation.times = {0.0f, 1.0f, 2.0f};
      anim.rotation.values = {quat(1, 0, 0, 0), glm::angleAxis(0.6f, vec3(0, 0, 1)), quat(1, 0, 0, 0)};
      reg.emplace<Animation>(e, anim);
      if (parent != ecs::null_entity) reg.emplace<Parent>(e, Parent{parent});
      parent = e;
    }
  } else {
    for (int k = 0; k < 4; ++k)
      add(prim("box", vec3(1.0f, 3.0f, 1.0f)), at(vec3(-8.0f + 5.0f * float(k), 1.5f, -6.0f)),
          matte, Kinematics::Type::Static);
    const TriangleMesh blob = prim("sphere", vec3(1), 96);
    std::vector<vec3> wave = blob.positions, squash = blob.positions;
    for (vec3& p : wave) p *= 1.0f + 0.25f * std::sin(5.0f * p.y);
    for (vec3& p : squash) p = vec3(p.x * 1.6f, p.y * 0.5f, p.z * 1.6f);
    const ecs::Entity e = add(blob, at(vec3(3, 2, 2), vec3(1.5f)), glass, Kinematics::Type::Free);
    Animation anim;
    anim.vertices.times = {0.0f, 1.0f, 2.0f};
    anim.vertices.values = {blob.positions, wave, squash};
    reg.emplace<Animation>(e, anim);
    for (int i = 0; i < 2; ++i) {
      Animation bob;
      bob.translation.times = {0.0f, 1.0f, 2.0f};
      const vec3 c(-3.0f + 6.0f * float(i), 1.0f, 4.0f);
      bob.translation.values = {c, c + vec3(0, 2, 0), c};
      const ecs::Entity s = add(prim("sphere", vec3(1), 48), at(c), mirror, Kinematics::Type::Free);
      reg.emplace<Animation>(s, bob);
    }
  }
  const ecs::Entity cam = reg.create();
  Camera c;
  c.position = vec3(0, 6, 16);
  c.look_at = vec3(0, 1.5f, 0);
  reg.emplace<Camera>(cam, c);
  const ecs::Entity light = reg.create();
  reg.emplace<Transform>(light, at(vec3(4, 12, 8)));
  Light l;
  l.intensity = 400.0f;
  reg.emplace<Light>(light, l);
  return scene;
}

} // namespace

void section_paper(const Options& o) {
  const std::uint32_t size = std::max(16u, o.size / 2);
  std::printf("\n### The paper's configurations on two animated scenes (%ux%u, %u threads, frame "
              "ms: median of %d animated frames at 30 Hz, structure updates included)\n\n",
              size, size, o.threads, o.frames);
  std::printf("| scene | configuration | BVH only (native-bvh) | kd-tree + BVH (native) | Embree | "
              "kd+BVH speed-up over BVH only | of which updates, kd+BVH (ms) |\n|---|---|---:|---:|---:|---:|---:|\n");
  struct Config {
    const char* name;
    TraceMode mode;
    bool shadows;
    std::uint32_t depth;
  };
  const Config configs[] = {{"diffuse", TraceMode::Whitted, false, 0},
                            {"+ shadows", TraceMode::Whitted, true, 0},
                            {"+ reflection & refraction", TraceMode::Whitted, false, 5},
                            {"all", TraceMode::Whitted, true, 5}};
  for (const bool deforming : {false, true}) {
    for (const Config& config : configs) {
      double result[3] = {0, 0, 0};
      double update_ms = 0.0;
      int k = 0;
      for (const char* backend : {"native-bvh", "native", "embree"}) {
        Scene scene = paper_scene(o, deforming);
        RenderJob job;
        job.backend = backend;
        job.native_wide_bvh = o.native_wide_bvh;
        job.settings.mode = config.mode;
        job.settings.shadows = config.shadows;
        job.settings.max_depth = config.depth;
        job.settings.threads = o.threads;
        job.image = Framebuffer(size, size);
        prepare_rendering(scene.registry, std::move(job));
        Schedule schedule;
        schedule.tick(scene.registry, 0.0); // first build: not a frame of the animation
        std::vector<double> ms, acc;
        for (int f = 0; f < o.frames; ++f) {
          ms.push_back(time_ms([&] { schedule.tick(scene.registry, 1.0 / 30.0); }));
          acc.push_back(scene.registry.resource<RenderJob>().last.accel.ms);
        }
        result[k] = median(ms);
        if (k == 1) update_ms = median(acc);
        ++k;
      }
      std::printf("| %s | %s | %.1f | %.1f | %.1f | %.2f | %.2f |\n",
                  deforming ? "deforming" : "orbits", config.name, result[0], result[1], result[2],
                  result[0] / result[1], update_ms);
      std::fflush(stdout);
    }
  }
}

} // namespace specula::bench
