// The Vulkan backends beside the CPU ones, in the same run (issue 10's benchmarks): primary rays
// per second on the bunny and the Cornell box for each kernel style and structure — whole frames
// on the device as a wavefront and as a single kernel, the CPU cast integrator over GPU
// traversal, the uniform grid — against native-bvh, native-grid and Embree, as ratios; then a
// sweep of the grid's resolution on the device and on the CPU, with the mean traversal steps and
// triangle tests per ray (Purcell et al. chose theirs by that balance); then hybrid mode (primary
// visibility rasterised, the rest traced) against fully traced device frames, frames per second
// in the same run and the PSNR between the images; path and shadow frames in both kernel styles
// against the CPU integrators; last the ray-cache cubes on the device.
//
// Every tracer comes from the factory (make_tracer), so this file names no backend type, and a
// configuration the machine or build cannot run is reported in its row ("n/a: why") rather than
// ending the run: the section runs unchanged on lavapipe, on a GPU machine, and without Vulkan.

#include "bench_common.h"
#include "specula/accel/grid/grid.h"
#include "specula/cache/ray_cache.h"
#include "specula/core/error.h"
#include "specula/image/framebuffer.h"
#include "specula/image/metrics.h"
#include "specula/render/render_job.h"
#include "specula/render/scene_layer.h"
#include "specula/render/tracer_factory.h"
#include "specula/scene/scene.h"
#include "specula/systems/schedule.h"
#include "specula/trace/camera_rays.h"
#include "specula/trace/render_frame.h"
#include "specula/trace/stats.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <exception>
#include <limits>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace specula::bench {

namespace {

/// One tracer configuration of the table.
struct Config {
  const char* label;
  const char* backend;
  GpuTracerOptions gpu;
};

std::vector<Config> configs() {
  GpuTracerOptions wavefront;
  GpuTracerOptions single;
  single.execution = GpuTracerOptions::Execution::single_kernel;
  GpuTracerOptions over_gpu;
  over_gpu.device_frames = false;
  return {{"embree", "embree", {}},
          {"native-bvh", "native-bvh", {}},
          {"native-grid", "native-grid", {}},
          {"vulkan, wavefront (device frames)", "vulkan", wavefront},
          {"vulkan, single kernel (device frames)", "vulkan", single},
          {"vulkan, CPU cast over GPU traversal", "vulkan", over_gpu},
          {"vulkan-grid, wavefront (device frames)", "vulkan-grid", wavefront},
          {"vulkan-grid, single kernel (device frames)", "vulkan-grid", single}};
}

/// What one configuration measured: the median frame, or why it could not run.
struct Measured {
  double mrays = 0.0;     ///< primary rays per second of wall-clock frame time
  double gpu_mrays = 0.0; ///< per second of device (timestamp) time; 0: no device or no timing
  std::optional<TracerDevice> device;
  std::string failure;
};

Measured measure(const Options& o, const Config& c, const SceneLayer& layer, const Camera& camera,
                 std::uint32_t width, std::uint32_t height) {
  Measured m;
  try {
    TracerOptions options;
    options.packet_width = 8;
    options.gpu = c.gpu;
    const std::unique_ptr<Tracer> tracer = make_tracer(c.backend, options);
    tracer->update(layer);
    TraceSettings settings;
    settings.mode = TraceMode::Cast;
    settings.threads = o.threads;
    Framebuffer image(width, height);
    (void)render_frame(*tracer, layer, camera, settings, image); // warm-up: pipelines, uploads
    std::vector<double> ms, gpu_ms;
    for (int r = 0; r < o.repetitions; ++r) {
      ms.push_back(time_ms([&] { (void)render_frame(*tracer, layer, camera, settings, image); }));
      if (const auto d = tracer_device(*tracer)) gpu_ms.push_back(d->gpu_ms);
    }
    const std::uint64_t rays = std::uint64_t(width) * height;
    m.mrays = mrays(rays, median(ms));
    m.device = tracer_device(*tracer);
    if (!gpu_ms.empty() && median(gpu_ms) > 0.0) m.gpu_mrays = mrays(rays, median(gpu_ms));
  } catch (const std::exception& e) {
    // Unavailable here, or the kernels are not there yet: say so in the row.
    m.failure = one_line(e.what(), 120);
  }
  return m;
}

std::string fixed(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.2f", value);
  return text;
}

/// a / b, or empty when b was not measured.
std::string ratio(double a, double b) { return b > 0.0 ? fixed(a / b) : std::string(); }

/// A scene as the whole-frame tables render it: its layer synced, its active camera, its size.
struct SceneView {
  SceneLayer layer;
  Camera camera;
  std::uint32_t width, height;
  explicit SceneView(Scene& scene)
      : camera(*active_camera(scene.registry)), width(scene.settings.width),
        height(scene.settings.height) {
    layer.sync(scene.registry);
  }
};

void table(const Options& o, const char* title, Scene& scene) {
  const SceneView view(scene);
  const SceneLayer& layer = view.layer;
  const Camera& camera = view.camera;
  const std::uint32_t width = view.width, height = view.height;
  std::printf("\n### Vulkan beside the CPU backends: %s, %ux%u primary rays (cast), %u CPU "
              "threads\n\n",
              title, width, height, o.threads);
  std::printf("| configuration | Mrays/s | × native-bvh | × embree | GPU-time Mrays/s | "
              "device |\n|---|---:|---:|---:|---:|---|\n");
  std::vector<Measured> rows;
  for (const Config& c : configs()) rows.push_back(measure(o, c, layer, camera, width, height));
  const double bvh = rows[1].mrays;
  const double embree = rows[0].mrays;
  std::size_t i = 0;
  for (const Config& c : configs()) {
    const Measured& m = rows[i++];
    if (!m.failure.empty()) {
      std::printf("| %s | n/a | | | | %s |\n", c.label, m.failure.c_str());
      continue;
    }
    const std::string device = m.device ? m.device->name + " (" + m.device->type + ")" : "CPU";
    std::printf("| %s | %.2f | %s | %s | %s | %s |\n", c.label, m.mrays,
                ratio(m.mrays, bvh).c_str(), ratio(m.mrays, embree).c_str(),
                m.gpu_mrays > 0.0 ? fixed(m.gpu_mrays).c_str() : "", device.c_str());
  }
  std::fflush(stdout);
}

/// Mean work per ray of the native grid's walk (UniformGrid's own counters).
struct GridWork {
  double cells = 0.0, tests = 0.0;
};

GridWork native_grid_work(const TriangleMesh& mesh, float density, const std::vector<Ray>& rays) {
  accel::UniformGrid grid;
  grid.build({mesh.positions.data(), mesh.triangles.data(), std::uint32_t(mesh.triangles.size())},
             {density});
  GridWork w;
  for (const Ray& ray : rays) {
    accel::PreparedRay r = accel::PreparedRay::make(ray);
    accel::TriangleHit hit;
    accel::GridTraceInfo info;
    (void)grid.intersect(r, hit, accel::TriangleTest::watertight, &info);
    w.cells += info.cells_visited;
    w.tests += info.triangles_tested;
  }
  w.cells /= double(rays.size());
  w.tests /= double(rays.size());
  return w;
}

/// Median ms of tracing `rays` in one intersect call (the device: one batch) or, for a CPU
/// tracer, in blocks over `threads` threads.
double time_batch(const Options& o, const Tracer& tracer, const std::vector<Ray>& rays,
                  std::vector<Hit>& hits, bool on_device) {
  const auto run = [&] {
    if (on_device) {
      tracer.intersect(rays, hits);
      return;
    }
    constexpr std::size_t kBlock = 4096;
    tbb::task_arena arena{static_cast<int>(o.threads)};
    arena.execute([&] {
      tbb::parallel_for(std::size_t(0), (rays.size() + kBlock - 1) / kBlock, [&](std::size_t b) {
        const std::size_t first = b * kBlock, n = std::min(kBlock, rays.size() - first);
        tracer.intersect(std::span(rays).subspan(first, n), std::span(hits).subspan(first, n));
      });
    });
  };
  run(); // warm-up: pipelines, uploads
  std::vector<double> ms;
  for (int r = 0; r < o.repetitions; ++r) ms.push_back(time_ms(run));
  return median(ms);
}

/// The camera's primary rays, row by row.
std::vector<Ray> camera_rays(Scene& scene) {
  const std::uint32_t width = scene.settings.width, height = scene.settings.height;
  const CameraRays camera(*active_camera(scene.registry), width, height);
  std::vector<Ray> rays;
  rays.reserve(std::size_t(width) * height);
  for (std::uint32_t y = 0; y < height; ++y)
    for (std::uint32_t x = 0; x < width; ++x) rays.push_back(camera.ray(x, y));
  return rays;
}

bool same_hit(const Hit& a, const Hit& b) {
  const auto bits = [](float f) { return std::bit_cast<std::uint32_t>(f); };
  if (a.instance != b.instance) return false;
  return !a.hit() || (a.primitive == b.primitive && bits(a.t) == bits(b.t) &&
                      bits(a.uv.x) == bits(b.uv.x) && bits(a.uv.y) == bits(b.uv.y));
}

/// Traversal alone (the lavapipe target): the primary rays in one batch through
/// trace_rays.comp against the native backend's scalar traversal of the same structure over the
/// CPU threads, and whether every hit is the same to the bit.
void traversal_table(const Options& o, Scene& scene) {
  SceneLayer layer;
  layer.sync(scene.registry);
  const std::vector<Ray> rays = camera_rays(scene);
  std::printf("\n### Traversal alone: bunny, %ux%u primary rays in one batch, %u CPU threads\n\n"
              "| tracer | Mrays/s | × native-bvh | device-time Mrays/s | dispatches | hits bit-identical "
              "to native |\n|---|---:|---:|---:|---:|---|\n",
              scene.settings.width, scene.settings.height, o.threads);
  std::vector<Hit> reference(rays.size()), hits(rays.size());
  double native_bvh = 0.0;
  // The reference is the device's own traversal in scalar C++: the binary BVH, one box per step.
  // native-bvh's default, the 4-wide SIMD collapse (wide_bvh.h), is a different walk and follows
  // as its own row; the ratios stay against the scalar one, as the target states.
  constexpr const char* kWide = "native-bvh (4-wide SIMD)";
  for (const char* name : {"native-bvh", "vulkan", "native-grid", "vulkan-grid", "embree", kWide}) {
    const bool wide = std::string_view(name) == kWide;
    const bool device = std::string_view(name).starts_with("vulkan");
    try {
      TracerOptions options;
      options.packet_width = 8;
      options.native_wide_bvh = wide;
      const std::unique_ptr<Tracer> tracer = make_tracer(wide ? "native-bvh" : name, options);
      tracer->update(layer);
      const double m = mrays(rays.size(), time_batch(o, *tracer, rays, hits, device));
      std::string same;
      if (std::string_view(name).starts_with("native") && !wide) {
        reference = hits;
      } else if (device) {
        std::size_t differ = 0;
        for (std::size_t i = 0; i < rays.size(); ++i) differ += same_hit(hits[i], reference[i]) ? 0 : 1;
        same = differ == 0 ? "yes" : std::to_string(differ) + " differ";
      }
      if (std::string_view(name) == "native-bvh") native_bvh = m;
      const std::optional<TracerDevice> d = tracer_device(*tracer);
      std::printf("| %s | %.2f | %s | %s | %s | %s |\n", name, m, ratio(m, native_bvh).c_str(),
                  d && d->gpu_ms > 0.0 ? fixed(mrays(rays.size(), d->gpu_ms)).c_str() : "",
                  d ? std::to_string(d->dispatches).c_str() : "", same.c_str());
    } catch (const std::exception& e) {
      std::printf("| %s | n/a | | | | %s |\n", name, one_line(e.what(), 100).c_str());
    }
    std::fflush(stdout);
  }
}

void grid_sweep(const Options& o, const TriangleMesh& mesh, Scene& scene) {
  SceneLayer layer;
  layer.sync(scene.registry);
  const std::uint32_t width = scene.settings.width, height = scene.settings.height;
  const std::vector<Ray> rays = camera_rays(scene);
  std::vector<Hit> hits(rays.size());
  std::printf("\n### Grid resolution sweep: bunny, %ux%u primary rays in one batch, %u CPU "
              "threads\n\nvulkan-grid traces them with trace_rays.comp (its steps: cells entered, "
              "triangles tested, set-up); native-grid with the same grid on the CPU.\n\n",
              width, height, o.threads);
  std::printf("| cells per triangle | vulkan-grid Mrays/s | native-grid Mrays/s | × native-grid "
              "| device steps/ray | device tests/ray | native cells/ray | native tests/ray | cut "
              "|\n|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const float density : {0.25f, 0.5f, 1.0f, 2.0f, 4.0f, 8.0f, 16.0f}) {
    const GridWork w = native_grid_work(mesh, density, rays);
    TracerOptions options;
    options.packet_width = 8;
    options.gpu.grid_density = density;
    options.gpu.count_tests = true;
    const std::unique_ptr<Tracer> native = make_tracer("native-grid", options);
    native->update(layer);
    const double native_mrays = mrays(rays.size(), time_batch(o, *native, rays, hits, false));
    std::string device = "n/a", ratio_text, steps, tests, cut;
    try {
      const std::unique_ptr<Tracer> gpu = make_tracer("vulkan-grid", options);
      gpu->update(layer);
      const double gpu_mrays = mrays(rays.size(), time_batch(o, *gpu, rays, hits, true));
      const TracerDevice d = tracer_device(*gpu).value_or(TracerDevice{});
      device = fixed(gpu_mrays);
      ratio_text = ratio(gpu_mrays, native_mrays);
      steps = fixed(double(d.steps) / double(rays.size()));
      tests = fixed(double(d.tests) / double(rays.size()));
      cut = std::to_string(d.cut);
    } catch (const std::exception& e) {
      device = "n/a: " + one_line(e.what(), 80);
    }
    std::printf("| %g | %s | %.2f | %s | %s | %s | %.2f | %.2f | %s |\n", double(density),
                device.c_str(), native_mrays, ratio_text.c_str(), steps.c_str(), tests.c_str(),
                w.cells, w.tests, cut.c_str());
    std::fflush(stdout);
  }
}

/// Hybrid mode against traced primary visibility: the same device frames (wavefront) but for
/// where the primary hits come from, cast and Whitted, with the share of primary rays hybrid mode
/// still traces (instance boundaries, raster misses) and the PSNR of the hybrid image against the
/// traced one (its error: pixels whose nearest triangle the raster decides differently).
void hybrid_table(const Options& o, const char* title, Scene& scene) {
  const SceneView view(scene);
  const SceneLayer& layer = view.layer;
  const Camera& camera = view.camera;
  const std::uint32_t width = view.width, height = view.height;
  std::printf("\n### Hybrid mode (--gpu-primary raster) against traced primary rays: %s, %ux%u, "
              "wavefront device frames\n\n",
              title, width, height);
  std::printf("| mode | traced frames/s | hybrid frames/s | × traced | traced GPU ms | hybrid GPU "
              "ms | primary rays traced in hybrid | PSNR hybrid vs traced (dB) |\n"
              "|---|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const TraceMode mode : {TraceMode::Cast, TraceMode::Whitted}) {
    struct Run {
      double ms = 0.0, gpu_ms = 0.0;
      std::uint64_t retraced = 0;
      Framebuffer image;
    };
    const auto run = [&](GpuTracerOptions::Primary primary) {
      TracerOptions options;
      options.gpu.primary = primary;
      const std::unique_ptr<Tracer> tracer = make_tracer("vulkan", options);
      tracer->update(layer);
      TraceSettings settings;
      settings.mode = mode;
      settings.threads = o.threads;
      Run r{0.0, 0.0, 0, Framebuffer(width, height)};
      (void)render_frame(*tracer, layer, camera, settings, r.image); // warm-up
      std::vector<double> ms, gpu_ms;
      for (int i = 0; i < o.repetitions; ++i) {
        ms.push_back(
            time_ms([&] { (void)render_frame(*tracer, layer, camera, settings, r.image); }));
        gpu_ms.push_back(tracer_device(*tracer).value_or(TracerDevice{}).gpu_ms);
      }
      r.ms = median(ms);
      r.gpu_ms = median(gpu_ms);
      r.retraced = tracer_device(*tracer).value_or(TracerDevice{}).retraced;
      return r;
    };
    try {
      const Run traced = run(GpuTracerOptions::Primary::trace);
      const Run hybrid = run(GpuTracerOptions::Primary::raster);
      std::printf("| %s | %.2f | %.2f | %s | %.2f | %.2f | %.1f%% | %.1f |\n",
                  trace_mode_name(mode), 1000.0 / traced.ms, 1000.0 / hybrid.ms,
                  ratio(traced.ms, hybrid.ms).c_str(), traced.gpu_ms, hybrid.gpu_ms,
                  100.0 * double(hybrid.retraced) / (double(width) * height),
                  psnr(traced.image, hybrid.image));
    } catch (const std::exception& e) {
      std::printf("| %s | n/a | | | | | | %s |\n", trace_mode_name(mode),
                  one_line(e.what(), 120).c_str());
    }
  }
  std::fflush(stdout);
}

/// Path and shadow frames in both execution styles (device_path.h) beside the CPU integrators on
/// native-bvh: median frame ms, device (timestamp) ms, rays per second of frame time, the single
/// kernel's frame time against the wavefront's on the same structure, and the share of pixels
/// equal to the wavefront's image (100%: bit for bit, as tested).
void stochastic_table(const Options& o, const char* title, Scene& scene) {
  const SceneView view(scene);
  const SceneLayer& layer = view.layer;
  const Camera& camera = view.camera;
  const std::uint32_t width = view.width, height = view.height;
  std::printf("\n### Path (1 spp, depth 5) and shadow (4 area samples) frames by execution style: "
              "%s, %ux%u, %u CPU threads\n\n",
              title, width, height, o.threads);
  std::printf("| mode | configuration | frame ms | GPU ms | Mrays/s | single ÷ wavefront time | "
              "pixels equal to the wavefront's |\n|---|---|---:|---:|---:|---:|---:|\n");
  GpuTracerOptions single;
  single.execution = GpuTracerOptions::Execution::single_kernel;
  const std::vector<Config> rows = {{"native-bvh (CPU integrator)", "native-bvh", {}},
                                    {"vulkan, wavefront", "vulkan", {}},
                                    {"vulkan, single kernel", "vulkan", single},
                                    {"vulkan-grid, wavefront", "vulkan-grid", {}},
                                    {"vulkan-grid, single kernel", "vulkan-grid", single}};
  for (const TraceMode mode : {TraceMode::Path, TraceMode::Shadow}) {
    TraceSettings settings;
    settings.mode = mode;
    settings.threads = o.threads;
    settings.max_depth = 5;
    settings.spp = 1;
    settings.shadow_samples = 4;
    settings.seed = 1;
    double wavefront_ms = 0.0;
    Framebuffer wavefront_image(width, height);
    for (const Config& c : rows) {
      try {
        TracerOptions options;
        options.gpu = c.gpu;
        const std::unique_ptr<Tracer> tracer = make_tracer(c.backend, options);
        tracer->update(layer);
        Framebuffer image(width, height);
        (void)render_frame(*tracer, layer, camera, settings, image); // warm-up: pipelines
        std::vector<double> ms, gpu_ms;
        std::uint64_t rays = 0;
        for (int r = 0; r < o.repetitions; ++r) {
          FrameStats stats;
          ms.push_back(
              time_ms([&] { stats = render_frame(*tracer, layer, camera, settings, image); }));
          rays = stats.rays.total();
          if (const auto d = tracer_device(*tracer)) gpu_ms.push_back(d->gpu_ms);
        }
        const double frame = median(ms);
        const bool device = tracer_device(*tracer).has_value();
        const bool is_wavefront = device && c.gpu.execution == GpuTracerOptions::Execution::wavefront;
        if (is_wavefront) {
          wavefront_ms = frame;
          wavefront_image = image;
        }
        std::string against, equal;
        if (device && !is_wavefront && wavefront_ms > 0.0) {
          against = ratio(frame, wavefront_ms);
          std::size_t same = 0;
          for (std::size_t i = 0; i < image.pixels().size(); ++i)
            same += image.pixels()[i] == wavefront_image.pixels()[i];
          char text[32];
          std::snprintf(text, sizeof text, "%.3f%%",
                        100.0 * double(same) / double(image.pixels().size()));
          equal = text;
        }
        std::printf("| %s | %s | %.1f | %s | %.2f | %s | %s |\n", trace_mode_name(mode), c.label,
                    frame, gpu_ms.empty() ? "" : fixed(median(gpu_ms)).c_str(),
                    mrays(rays, frame), against.c_str(), equal.c_str());
      } catch (const std::exception& e) {
        std::printf("| %s | %s | n/a | | | | %s |\n", trace_mode_name(mode), c.label,
                    one_line(e.what(), 120).c_str());
      }
      std::fflush(stdout);
    }
  }
}

} // namespace

/// Ray-cache cubes on the device (issue 10): the mirror-spheres scene with 32 spheres on the
/// vulkan backend's device Whitted frames, uncached, with --cache on (direction mode) and with
/// --cache auto (40 dB), ticked in turn in one run while the camera pans, frames/s of each and the
/// PSNR of every cached frame against the uncached frame of the same view. The first frames fill
/// the cubes; the figures after them are the steady state. The frames stay on the device, as a
/// window presents them (keep_frames_on_device): the timed tick is the frame a game shows; the
/// ones compared are read back afterwards, untimed. (Auto frames in which a cube is on trial in
/// march mode run on the CPU integrators over GPU traversal, into the host image.)
void section_gpu_cache(const Options& o) {
  std::printf("\n### Ray-cache cubes on the device (mirror_spheres_32, vulkan wavefront, %ux%u, "
              "pan 0.25°/frame, frames kept on the device as a window presents them)\n\n",
              o.size, o.size);
  // Frames 4-8: the cubes just filled (auto still trying its modes); 41-48: settled.
  constexpr int kEarly = 3, kFill = 40, kFrames = 48;
  struct Run {
    const char* label;
    cache::CachePolicy policy;
    Scene scene;
    Schedule schedule;
    std::vector<double> ms;
    double psnr_min = std::numeric_limits<double>::infinity(), psnr_sum = 0.0;
    std::uint64_t hits = 0, lookups = 0;
    std::uint64_t dropped = 0; ///< rays not traced over the run (a cut tree): must be 0
  };
  std::vector<std::unique_ptr<Run>> runs;
  try {
    for (const auto& [label, policy] :
         {std::pair{"uncached", cache::CachePolicy::Off},
          std::pair{"cached (on, direction)", cache::CachePolicy::On},
          std::pair{"cached (auto, 40 dB)", cache::CachePolicy::Auto}}) {
      auto run = std::make_unique<Run>();
      run->label = label;
      run->policy = policy;
      run->scene = load_scene(o.source_dir + "/samples/scenes/mirror_spheres_32.json");
      RenderJob job;
      job.backend = "vulkan";
      job.settings.mode = TraceMode::Whitted;
      job.settings.threads = o.threads;
      job.settings.max_depth = run->scene.settings.max_depth;
      job.settings.min_weight = 1.0f / 256.0f;
      job.settings.background = run->scene.settings.background;
      job.image = Framebuffer(o.size, o.size);
      job.cache.policy = policy;
      job.cache.lookup = cache::LookupMode::Direction;
      job.cache.max_error_db = 40.0f;
      prepare_rendering(run->scene.registry, std::move(job));
      run->schedule.tick(run->scene.registry, 0.0); // builds, and renders a first frame
      (void)keep_frames_on_device(*run->scene.registry.resource<ActiveTracer>().tracer, true);
      runs.push_back(std::move(run));
    }
  } catch (const std::exception& e) {
    std::printf("n/a: %s\n", one_line(e.what()).c_str());
    return;
  }
  const Camera start = *active_camera(runs[0]->scene.registry);
  for (int f = 0; f < kFrames; ++f) {
    const float a = glm::radians(0.25f * float(f + 1));
    const vec3 c(start.look_at), d = vec3(start.position) - c;
    const vec3 p = c + vec3(d.x * std::cos(a) + d.z * std::sin(a), d.y,
                            -d.x * std::sin(a) + d.z * std::cos(a));
    for (auto& run : runs) {
      run->scene.registry.view<Camera>().each([&](Camera& cam) { cam.position = p; });
      run->ms.push_back(time_ms([&] { run->schedule.tick(run->scene.registry, 0.0); }));
      run->dropped += run->scene.registry.resource<RenderJob>().last.rays.dropped;
    }
    if (f < kFill) continue;
    for (auto& run : runs) {
      const Tracer& tracer = *run->scene.registry.resource<ActiveTracer>().tracer;
      if (device_frame(tracer) != nullptr)
        read_back_frame(tracer, run->scene.registry.resource<RenderJob>().image);
    }
    for (std::size_t k = 1; k < runs.size(); ++k) {
      Run& r = *runs[k];
      const double q = psnr(runs[0]->scene.registry.resource<RenderJob>().image,
                            r.scene.registry.resource<RenderJob>().image);
      r.psnr_min = std::min(r.psnr_min, q);
      r.psnr_sum += q;
      const CacheCounts& n = r.scene.registry.resource<cache::RayCaches>().store->counts();
      r.hits += n.hits;
      r.lookups += n.lookups;
    }
  }
  auto fps = [&](const Run& r, int from, int to) {
    std::vector<double> window(r.ms.begin() + from, r.ms.begin() + to);
    std::sort(window.begin(), window.end());
    return 1000.0 / window[window.size() / 2];
  };
  const auto db = [](double v) { return std::isinf(v) ? std::string("identical") : fixed(v) + " dB"; };
  const double early = fps(*runs[0], kEarly, kEarly + 5), settled = fps(*runs[0], kFill, kFrames);
  std::printf(
      "| | frames/s, frames %d-%d | ratio | frames/s, frames %d-%d | ratio | PSNR vs uncached "
      "(mean, min; frames %d-%d) | lookups served | rays dropped |\n"
      "|---|---:|---:|---:|---:|---|---:|---:|\n",
      kEarly + 1, kEarly + 5, kFill + 1, kFrames, kFill + 1, kFrames);
  std::printf("| uncached | %s | 1.00 | %s | 1.00 | | | %llu |\n", fixed(early).c_str(),
              fixed(settled).c_str(), static_cast<unsigned long long>(runs[0]->dropped));
  for (std::size_t k = 1; k < runs.size(); ++k) {
    const Run& r = *runs[k];
    const double e = fps(r, kEarly, kEarly + 5), st = fps(r, kFill, kFrames);
    std::printf("| %s | %s | %s | %s | %s | %s, %s | %.1f%% | %llu |\n", r.label, fixed(e).c_str(),
                ratio(e, early).c_str(), fixed(st).c_str(), ratio(st, settled).c_str(),
                db(r.psnr_sum / (kFrames - kFill)).c_str(), db(r.psnr_min).c_str(),
                r.lookups > 0 ? 100.0 * double(r.hits) / double(r.lookups) : 0.0,
                static_cast<unsigned long long>(r.dropped));
  }
  std::fflush(stdout);
}

void section_gpu_path(const Options& o) {
  Scene cornell = load_scene(o.source_dir + "/samples/scenes/cornell_box.json");
  cornell.settings.width = cornell.settings.height = o.size;
  stochastic_table(o, "Cornell box", cornell);
}

namespace {

void device_list() {
  std::string why;
  std::printf("\n### Vulkan devices\n\n");
  for (const VulkanDeviceEntry& d : vulkan_devices(&why))
    std::printf("- %s (%s)%s\n", d.name.c_str(), d.type.c_str(), d.chosen ? " — used" : "");
  if (!why.empty()) std::printf("- none used: %s\n", one_line(why).c_str());
}

} // namespace

void section_gpu_traversal(const Options& o) {
  device_list();
  Scene bunny = mesh_scene(load_bunny(o), o.size);
  traversal_table(o, bunny);
}

void section_gpu(const Options& o) {
  device_list();
  const TriangleMesh bunny_mesh = load_bunny(o);
  Scene bunny = mesh_scene(bunny_mesh, o.size);
  traversal_table(o, bunny);
  table(o, "bunny", bunny);
  Scene cornell = load_scene(o.source_dir + "/samples/scenes/cornell_box.json");
  cornell.settings.width = cornell.settings.height = o.size;
  table(o, "Cornell box", cornell);
  grid_sweep(o, bunny_mesh, bunny);
  hybrid_table(o, "Cornell box", cornell);
  stochastic_table(o, "Cornell box", cornell);
  Scene spheres = load_scene(o.source_dir + "/samples/scenes/mirror_spheres_8.json");
  spheres.settings.width = spheres.settings.height = o.size;
  hybrid_table(o, "mirror spheres (8)", spheres);
  section_gpu_cache(o);
}

} // namespace specula::bench
