// specula_bench: speed against error, measured in one run so ratios are meaningful on a noisy,
// shared machine. Every comparison interleaves its contenders repetition by repetition and
// reports medians; docs/PERFORMANCE.md records the output with the command that produced it.
//
// Sections:
//   primary  Specula's primary-ray stage (ray generation, packets, hits resolved to surfaces:
//            the tracer's own overhead) against Embree in a minimal loop with the same rays,
//            tiles and threads, per packet width; and the whole cast mode (plus local shading and
//            image writes) beside it.
//   tiles    8×8 against 16×16 tiles.
//   whitted  Whitted frame times on the mirror-spheres family and the Cornell box.
//   depth    speed against error of the depth and weight cut-offs (reference: depth 32, no
//            cut-off), with RMSE, PSNR and FLIP on the same frames.

#include "specula/accel/embree/embree_tracer.h"
#include "specula/image/flip.h"
#include "specula/image/metrics.h"
#include "specula/render/render_job.h"
#include "specula/render/scene_layer.h"
#include "specula/scene/components.h"
#include "specula/scene/hierarchy.h"
#include "specula/scene/mesh_io.h"
#include "specula/scene/scene.h"
#include "specula/systems/schedule.h"
#include "specula/trace/camera_rays.h"
#include "specula/trace/packet_tile.h"
#include "specula/trace/render_frame.h"

#include <CLI/CLI.hpp>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Tools/Subdivider/Uniform/LoopT.hh>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <pmmintrin.h>
#include <xmmintrin.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

namespace {

using namespace specula;
using Clock = std::chrono::steady_clock;

struct Options {
  std::uint32_t size = 1024;
  std::uint32_t threads = 2;
  int repetitions = 7;
  int frames = 10;
  int subdivisions = 4;
  std::string sections = "primary,tiles,whitted,depth";
  std::string source_dir = SPECULA_SOURCE_DIR;
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

double time_ms(const std::function<void()>& f) {
  const auto start = Clock::now();
  f();
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

/// The bunny, Loop-subdivided `levels` times with OpenMesh (×4 triangles per level).
TriangleMesh subdivided(const TriangleMesh& base, int levels) {
  if (levels == 0) return base;
  using OMesh = OpenMesh::TriMesh_ArrayKernelT<>;
  OMesh om;
  std::vector<OMesh::VertexHandle> handles;
  for (const vec3& p : base.positions)
    handles.push_back(om.add_vertex(OMesh::Point(p.x, p.y, p.z)));
  for (const uvec3& t : base.triangles) om.add_face(handles[t.x], handles[t.y], handles[t.z]);
  OpenMesh::Subdivider::Uniform::LoopT<OMesh> loop;
  loop.attach(om);
  loop(static_cast<std::size_t>(levels));
  loop.detach();
  TriangleMesh out;
  for (const auto& v : om.vertices()) {
    const auto& p = om.point(v);
    out.positions.emplace_back(p[0], p[1], p[2]);
  }
  for (const auto& f : om.faces()) {
    uvec3 t;
    int k = 0;
    for (const auto& v : om.fv_range(f)) t[k++] = static_cast<std::uint32_t>(v.idx());
    out.triangles.push_back(t);
  }
  out.compute_vertex_normals();
  return out;
}

/// A scene holding one static mesh, with the default camera and light framing it.
Scene mesh_scene(const TriangleMesh& mesh, std::uint32_t size) {
  Scene scene;
  scene.settings.width = scene.settings.height = size;
  ecs::Registry& reg = scene.registry;
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e);
  reg.emplace<Mesh>(e, Mesh{std::make_shared<const TriangleMesh>(mesh), {}, {}, 0});
  reg.emplace<Material>(e);
  reg.emplace<Kinematics>(e);
  update_world_transforms(reg, 0);
  add_defaults(scene);
  return scene;
}

/// Embree alone: the same camera rays, tiles, packet footprints and thread arena as the
/// renderer, nothing else (no hit resolution, no shading, no image).
template <int N, typename RayHitN, typename IntersectN>
std::uint64_t embree_minimal_packets(RTCScene scene, const CameraRays& cam, std::uint32_t size,
                                     std::uint32_t threads, IntersectN intersect_n) {
  const std::uint32_t tile = 16;
  const std::uint32_t tiles_x = (size + tile - 1) / tile;
  std::atomic<std::uint64_t> checksum{0};
  tbb::task_arena arena{static_cast<int>(threads)};
  arena.execute([&] {
    tbb::parallel_for(
        tbb::blocked_range<std::uint32_t>(0, tiles_x * tiles_x, 1), [&](const auto& range) {
          _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
          _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
          RTCIntersectContext context;
          rtcInitIntersectContext(&context);
          context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
          std::uint64_t local = 0;
          for (std::uint32_t t = range.begin(); t != range.end(); ++t) {
            const std::uint32_t x0 = (t % tiles_x) * tile, y0 = (t / tiles_x) * tile;
            // The renderer's packet footprints (PacketTile), so both trace the same packets.
            const PacketTile footprint = PacketTile::for_width(x0, y0, std::min(x0 + tile, size),
                                                               std::min(y0 + tile, size), N);
            footprint.for_each_block([&](std::uint32_t bx, std::uint32_t by, std::uint32_t ex,
                                         std::uint32_t ey) {
              const std::uint32_t pw = footprint.packet_w;
              alignas(64) RayHitN rh;
              alignas(64) int valid[N];
              for (int i = 0; i < N; ++i) {
                const std::uint32_t x = bx + std::uint32_t(i) % pw, y = by + std::uint32_t(i) / pw;
                valid[i] =
                    (std::uint32_t(i) < pw * footprint.packet_h && x < ex && y < ey) ? -1 : 0;
                const Ray r = cam.ray(std::min(x, ex - 1), std::min(y, ey - 1));
                rh.ray.org_x[i] = r.origin.x;
                rh.ray.org_y[i] = r.origin.y;
                rh.ray.org_z[i] = r.origin.z;
                rh.ray.dir_x[i] = r.direction.x;
                rh.ray.dir_y[i] = r.direction.y;
                rh.ray.dir_z[i] = r.direction.z;
                rh.ray.tnear[i] = 0.0f;
                rh.ray.tfar[i] = r.tfar;
                rh.ray.time[i] = 0.0f;
                rh.ray.mask[i] = 0xFFFFFFFFu;
                rh.ray.id[i] = 0;
                rh.ray.flags[i] = 0;
                rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
                rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
              }
              intersect_n(valid, scene, &context, &rh);
              for (int i = 0; i < N; ++i) local += valid[i] ? rh.hit.primID[i] : 0;
            });
          }
          checksum += local;
        });
  });
  return checksum.load();
}

std::uint64_t embree_minimal_single(RTCScene scene, const CameraRays& cam, std::uint32_t size,
                                    std::uint32_t threads) {
  const std::uint32_t tile = 16;
  const std::uint32_t tiles_x = (size + tile - 1) / tile;
  std::atomic<std::uint64_t> checksum{0};
  tbb::task_arena arena{static_cast<int>(threads)};
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<std::uint32_t>(0, tiles_x * tiles_x, 1),
                      [&](const auto& range) {
                        _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
                        _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
                        RTCIntersectContext context;
                        rtcInitIntersectContext(&context);
                        std::uint64_t local = 0;
                        for (std::uint32_t t = range.begin(); t != range.end(); ++t) {
                          const std::uint32_t x0 = (t % tiles_x) * tile, y0 = (t / tiles_x) * tile;
                          for (std::uint32_t y = y0; y < std::min(y0 + tile, size); ++y)
                            for (std::uint32_t x = x0; x < std::min(x0 + tile, size); ++x) {
                              const Ray r = cam.ray(x, y);
                              RTCRayHit rh;
                              rh.ray.org_x = r.origin.x;
                              rh.ray.org_y = r.origin.y;
                              rh.ray.org_z = r.origin.z;
                              rh.ray.dir_x = r.direction.x;
                              rh.ray.dir_y = r.direction.y;
                              rh.ray.dir_z = r.direction.z;
                              rh.ray.tnear = 0.0f;
                              rh.ray.tfar = r.tfar;
                              rh.ray.time = 0.0f;
                              rh.ray.mask = 0xFFFFFFFFu;
                              rh.ray.id = 0;
                              rh.ray.flags = 0;
                              rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
                              rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
                              rtcIntersect1(scene, &context, &rh);
                              local += rh.hit.primID;
                            }
                        }
                        checksum += local;
                      });
  });
  return checksum.load();
}

std::uint64_t embree_minimal(RTCScene scene, const CameraRays& cam, std::uint32_t size,
                             std::uint32_t threads, std::uint32_t width) {
  switch (width) {
  case 16:
    return embree_minimal_packets<16, RTCRayHit16>(scene, cam, size, threads, rtcIntersect16);
  case 8:
    return embree_minimal_packets<8, RTCRayHit8>(scene, cam, size, threads, rtcIntersect8);
  case 4:
    return embree_minimal_packets<4, RTCRayHit4>(scene, cam, size, threads, rtcIntersect4);
  default:
    return embree_minimal_single(scene, cam, size, threads);
  }
}

double mrays(std::uint64_t rays, double ms) { return double(rays) / (ms * 1e3); }

void section_primary(const Options& o, const std::string& name, const TriangleMesh& mesh) {
  Scene scene = mesh_scene(mesh, o.size);
  SceneLayer layer;
  layer.sync(scene.registry);
  EmbreeTracer tracer;
  const double build_ms = time_ms([&] { tracer.update(layer); });
  const Camera camera = *active_camera(scene.registry);
  const CameraRays cam(camera, o.size, o.size);
  Framebuffer image(o.size, o.size);
  TraceSettings settings;
  settings.mode = TraceMode::Cast;
  settings.threads = o.threads;
  const std::uint64_t rays = std::uint64_t(o.size) * o.size;
  std::printf("\n### Primary rays: %s (%zu triangles), %ux%u, %u threads\n\n", name.c_str(),
              mesh.triangle_count(), o.size, o.size, o.threads);
  std::printf("Static build (Embree, high quality): %.1f ms.\n\n", build_ms);
  std::printf("| packet width | Embree minimal loop (Mrays/s) | Specula primary stage (Mrays/s) | "
              "primary / Embree | Specula cast mode, shaded (Mrays/s) | cast / Embree |\n");
  std::printf("|---:|---:|---:|---:|---:|---:|\n");
  for (const std::uint32_t w : {1u, 4u, 8u, 16u}) {
    tracer.set_packet_width(w);
    std::vector<double> embree_ms, primary_ms, cast_ms;
    // Warm-up, then interleave so all three see the same machine state.
    (void)embree_minimal(tracer.scene(), cam, o.size, o.threads, w);
    (void)trace_primary_frame(tracer, camera, o.size, o.size, settings);
    (void)render_frame(tracer, layer, camera, settings, image);
    for (int r = 0; r < o.repetitions; ++r) {
      embree_ms.push_back(
          time_ms([&] { (void)embree_minimal(tracer.scene(), cam, o.size, o.threads, w); }));
      primary_ms.push_back(
          time_ms([&] { (void)trace_primary_frame(tracer, camera, o.size, o.size, settings); }));
      cast_ms.push_back(
          time_ms([&] { (void)render_frame(tracer, layer, camera, settings, image); }));
    }
    const double e = mrays(rays, median(embree_ms));
    const double p = mrays(rays, median(primary_ms));
    const double c = mrays(rays, median(cast_ms));
    std::printf("| %u | %.1f | %.1f | %.2f | %.1f | %.2f |\n", w, e, p, p / e, c, c / e);
    std::fflush(stdout);
  }
}

void section_tiles(const Options& o, const TriangleMesh& mesh) {
  Scene scene = mesh_scene(mesh, o.size);
  SceneLayer layer;
  layer.sync(scene.registry);
  EmbreeTracer tracer;
  tracer.update(layer);
  const Camera camera = *active_camera(scene.registry);
  Framebuffer image(o.size, o.size);
  const std::uint64_t rays = std::uint64_t(o.size) * o.size;
  std::printf("\n### Tile size (bunny, cast mode, %ux%u, %u threads)\n\n", o.size, o.size,
              o.threads);
  std::printf("| packet width | 8×8 tiles (Mrays/s) | 16×16 tiles (Mrays/s) | 16×16 / 8×8 "
              "|\n|---:|---:|---:|---:|\n");
  for (const std::uint32_t w : {1u, 16u}) {
    tracer.set_packet_width(w);
    TraceSettings s8, s16;
    s8.mode = s16.mode = TraceMode::Cast;
    s8.threads = s16.threads = o.threads;
    s8.tile_size = 8;
    s16.tile_size = 16;
    std::vector<double> t8, t16;
    (void)render_frame(tracer, layer, camera, s16, image);
    for (int r = 0; r < o.repetitions; ++r) {
      t8.push_back(time_ms([&] { (void)render_frame(tracer, layer, camera, s8, image); }));
      t16.push_back(time_ms([&] { (void)render_frame(tracer, layer, camera, s16, image); }));
    }
    const double a = mrays(rays, median(t8)), b = mrays(rays, median(t16));
    std::printf("| %u | %.1f | %.1f | %.2f |\n", w, a, b, b / a);
  }
}

/// Renders `frames` frames of a scene file through the schedule; returns median ms and the image.
struct FrameRun {
  double median_ms = 0.0;
  double median_trace_ms = 0.0;
  RayCounts rays;
  Framebuffer image{1, 1};
};
FrameRun run_frames(const std::filesystem::path& path, std::uint32_t width, std::uint32_t height,
                    std::uint32_t threads, int frames, std::uint32_t max_depth, float min_weight) {
  Scene scene = load_scene(path);
  RenderJob job;
  job.backend = "embree";
  job.settings.mode = TraceMode::Whitted;
  job.settings.threads = threads;
  job.settings.max_depth = max_depth;
  job.settings.min_weight = min_weight;
  job.settings.background = scene.settings.background;
  job.image = Framebuffer(width, height);
  prepare_rendering(scene.registry, std::move(job));
  Schedule schedule;
  schedule.tick(scene.registry, 0.0); // builds the structures; not timed as a frame
  std::vector<double> ms, trace_ms;
  for (int f = 0; f < frames; ++f) {
    ms.push_back(time_ms([&] { schedule.tick(scene.registry, 0.0); }));
    trace_ms.push_back(scene.registry.resource<RenderJob>().last.trace_ms);
  }
  FrameRun run;
  run.median_ms = median(ms);
  run.median_trace_ms = median(trace_ms);
  run.rays = scene.registry.resource<RenderJob>().last.rays;
  run.image = scene.registry.resource<RenderJob>().image;
  return run;
}

void section_whitted(const Options& o) {
  const std::filesystem::path scenes = std::filesystem::path(o.source_dir) / "samples/scenes";
  std::printf("\n### Whitted frames (depth 5, weight cut-off 1/256, %u threads; the first frame's "
              "build excluded)\n\n",
              o.threads);
  std::printf("| scene | size | frame ms | frames/s | rays/frame | Mrays/s "
              "|\n|---|---|---:|---:|---:|---:|\n");
  const std::uint32_t cornell_w = std::max(16u, o.size / 2),
                      cornell_h = std::max(16u, o.size * 400 / 1024);
  std::vector<std::tuple<std::string, std::uint32_t, std::uint32_t>> runs = {
      {"cornell_box", cornell_w, cornell_h}};
  for (const int n : {0, 1, 2, 4, 8, 16, 32})
    runs.emplace_back("mirror_spheres_" + std::to_string(n), o.size, o.size);
  for (const auto& [name, w, h] : runs) {
    const FrameRun r =
        run_frames(scenes / (name + ".json"), w, h, o.threads, o.frames, 5, 1.0f / 256.0f);
    std::printf("| %s | %ux%u | %.1f | %.1f | %llu | %.1f |\n", name.c_str(), w, h, r.median_ms,
                1000.0 / r.median_ms, static_cast<unsigned long long>(r.rays.total()),
                mrays(r.rays.total(), r.median_trace_ms));
    std::fflush(stdout);
  }
}

void section_depth(const Options& o) {
  const std::filesystem::path scenes = std::filesystem::path(o.source_dir) / "samples/scenes";
  std::printf("\n### Depth and weight cut-offs: speed against error (reference: depth 32, no "
              "weight cut-off)\n\n");
  std::printf("| scene | max depth | weight cut-off | frame ms | speed-up | RMSE | PSNR (dB) | "
              "mean FLIP |\n|---|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const std::string name : {"cornell_box", "mirror_spheres_8"}) {
    const std::uint32_t w = name == "cornell_box" ? std::max(16u, o.size / 2) : o.size;
    const std::uint32_t h = name == "cornell_box" ? std::max(16u, o.size * 400 / 1024) : o.size;
    const auto path = scenes / (name + ".json");
    const FrameRun reference =
        run_frames(path, w, h, o.threads, std::max(1, o.frames / 2), 32, 0.0f);
    for (const auto& [depth, cutoff] :
         std::vector<std::pair<std::uint32_t, float>>{{1, 1.0f / 256},
                                                      {2, 1.0f / 256},
                                                      {3, 1.0f / 256},
                                                      {5, 1.0f / 256},
                                                      {5, 0.0f},
                                                      {8, 1.0f / 256}}) {
      const FrameRun r = run_frames(path, w, h, o.threads, o.frames, depth, cutoff);
      const double e = rmse(reference.image, r.image);
      const double p = psnr(reference.image, r.image);
      const double f = flip(reference.image, r.image).mean;
      std::printf("| %s | %u | %s | %.1f | %.2f | %.2e | %s | %.4f |\n", name.c_str(), depth,
                  cutoff > 0 ? "1/256" : "0", r.median_ms, reference.median_ms / r.median_ms, e,
                  std::isinf(p) ? "inf" : std::to_string(p).substr(0, 5).c_str(), f);
      std::fflush(stdout);
    }
    std::printf("| %s | 32 (reference) | 0 | %.1f | 1.00 | | | |\n", name.c_str(),
                reference.median_ms);
  }
}

} // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"Specula speed-against-error report (markdown on stdout)"};
  app.add_option("--size", o.size,
                 "Image side for primary rays and mirror spheres (Cornell: size/2 × size·400/1024)")
      ->check(CLI::Range(16u, 8192u));
  app.add_option("--threads", o.threads, "Worker threads")->check(CLI::Range(1u, 256u));
  app.add_option("--repetitions", o.repetitions, "Interleaved repetitions per comparison")
      ->check(CLI::Range(1, 1000));
  app.add_option("--frames", o.frames, "Frames per Whitted measurement")
      ->check(CLI::Range(1, 10000));
  app.add_option("--subdivisions", o.subdivisions,
                 "Loop subdivisions of the bunny for the large mesh")
      ->check(CLI::Range(0, 6));
  app.add_option("--sections", o.sections, "Comma-separated: primary,tiles,whitted,depth");
  app.add_option("--source-dir", o.source_dir, "Specula source tree (for samples/)");
  CLI11_PARSE(app, argc, argv);
  try {
    const auto has = [&](const char* s) { return o.sections.find(s) != std::string::npos; };
    std::printf(
        "## specula_bench --size %u --threads %u --repetitions %d --frames %d --subdivisions %d\n",
        o.size, o.threads, o.repetitions, o.frames, o.subdivisions);
    const TriangleMesh bunny =
        load_mesh_file(std::filesystem::path(o.source_dir) / "samples/models/bunny.obj");
    if (has("primary")) {
      section_primary(o, "bunny", bunny);
      if (o.subdivisions > 0) {
        const TriangleMesh big = subdivided(bunny, o.subdivisions);
        section_primary(o, "bunny, " + std::to_string(o.subdivisions) + "× Loop-subdivided", big);
      }
    }
    if (has("tiles")) section_tiles(o, bunny);
    if (has("whitted")) section_whitted(o);
    if (has("depth")) section_depth(o);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "specula_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
