// The Vulkan backends beside the CPU ones, in the same run (issue 10's benchmarks): primary rays
// per second on the bunny and the Cornell box for each kernel style and structure — whole frames
// on the device as a wavefront and as a single kernel, the CPU cast integrator over GPU
// traversal, the uniform grid — against native-bvh, native-grid and Embree, as ratios; then a
// sweep of the grid's resolution on the device and on the CPU, with the mean traversal steps and
// triangle tests per ray (Purcell et al. chose theirs by that balance).
//
// Every tracer comes from the factory (make_tracer), so this file names no backend type, and a
// configuration the machine or build cannot run is reported in its row ("n/a: why") rather than
// ending the run: the section runs unchanged on lavapipe, on a GPU machine, and without Vulkan.

#include "bench_common.h"
#include "specula/accel/grid/grid.h"
#include "specula/core/error.h"
#include "specula/image/framebuffer.h"
#include "specula/render/scene_layer.h"
#include "specula/render/tracer_factory.h"
#include "specula/scene/scene.h"
#include "specula/trace/camera_rays.h"
#include "specula/trace/render_frame.h"
#include "specula/trace/stats.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <bit>
#include <cstdio>
#include <exception>
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

void table(const Options& o, const char* title, Scene& scene) {
  SceneLayer layer;
  layer.sync(scene.registry);
  const Camera camera = *active_camera(scene.registry);
  const std::uint32_t width = scene.settings.width;
  const std::uint32_t height = scene.settings.height;
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
  for (const char* name : {"native-bvh", "vulkan", "native-grid", "vulkan-grid", "embree"}) {
    const bool device = std::string_view(name).starts_with("vulkan");
    try {
      TracerOptions options;
      options.packet_width = 8;
      const std::unique_ptr<Tracer> tracer = make_tracer(name, options);
      tracer->update(layer);
      const double m = mrays(rays.size(), time_batch(o, *tracer, rays, hits, device));
      std::string same;
      if (std::string_view(name).starts_with("native")) {
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

} // namespace

void section_gpu(const Options& o) {
  std::string why;
  std::printf("\n### Vulkan devices\n\n");
  for (const VulkanDeviceEntry& d : vulkan_devices(&why))
    std::printf("- %s (%s)%s\n", d.name.c_str(), d.type.c_str(), d.chosen ? " — used" : "");
  if (!why.empty()) std::printf("- none used: %s\n", one_line(why).c_str());
  const TriangleMesh bunny_mesh = load_bunny(o);
  Scene bunny = mesh_scene(bunny_mesh, o.size);
  traversal_table(o, bunny);
  table(o, "bunny", bunny);
  Scene cornell = load_scene(o.source_dir + "/samples/scenes/cornell_box.json");
  cornell.settings.width = cornell.settings.height = o.size;
  table(o, "Cornell box", cornell);
  grid_sweep(o, bunny_mesh, bunny);
}

} // namespace specula::bench
