#include "commands.h"

#include "specula/core/error.h"
#include "specula/core/memory_budget.h"
#include "specula/image/denoise.h"
#include "specula/image/image_io.h"
#include "specula/render/render_job.h"
#include "specula/render/tracer_factory.h"
#include "specula/scene/scene.h"
#include "specula/systems/schedule.h"
#include "specula/trace/stats.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cstdio>
#include <ostream>
#include <utility>

namespace specula::cli {

// One limit per quantity: what a scene file may set is what the CLI and the framebuffer take.
static_assert(kMaxImageSide == kMaxFramebufferSide);

namespace {

nlohmann::json vec_json(const vec3& v) { return {v.x, v.y, v.z}; }

std::string shown_number(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%g", value);
  return text;
}

/// The scene-time range of an animated render (`--time T0:T1`).
struct TimeRange {
  double t0 = 0.0;
  double t1 = 0.0;
};

/// The animation range a scene file gives (AFF's `a START END FRAMES`, JSON's
/// settings.animation): `--time` left out renders it. None when the file gives none, or a start
/// before 0 (the schedule's clock starts at 0; such a file still renders with --time).
std::optional<TimeRange> scene_time_range(const Scene& scene) {
  const RenderSettings& s = scene.settings;
  if (s.anim_frames == 0 || !(s.anim_start >= 0.0) || !(s.anim_end >= s.anim_start))
    return std::nullopt;
  return TimeRange{s.anim_start, s.anim_end};
}

/// "T0:T1" → the range; a clear error naming --time for anything else.
TimeRange parse_time_range(const std::string& text) {
  const auto bad = [&] {
    return Error("--time", "expected T0:T1 in seconds with 0 <= T0 <= T1 <= 1e9, got '" +
                               printable(text) + "'");
  };
  const std::size_t colon = text.find(':');
  if (colon == std::string::npos) throw bad();
  double v[2] = {};
  const std::string parts[2] = {text.substr(0, colon), text.substr(colon + 1)};
  for (int i = 0; i < 2; ++i) {
    const char* first = parts[i].data();
    const char* last = first + parts[i].size();
    const auto [end, ec] = std::from_chars(first, last, v[i]);
    if (parts[i].empty() || ec != std::errc() || end != last) throw bad();
  }
  // Animation clocks are floats: beyond 1e9 s a frame step of 1/60 s would be lost.
  if (!(v[0] >= 0.0 && v[0] <= v[1] && v[1] <= 1e9)) throw bad();
  return {v[0], v[1]};
}

bool power_of_two(std::uint32_t v) { return v >= 1 && v <= 4096 && (v & (v - 1)) == 0; }

/// --cache and its companions → the job's cache settings.
cache::CacheSettings parse_cache(const RenderOptions& o) {
  cache::CacheSettings c;
  if (const auto policy = cache::parse_cache_policy(o.cache)) {
    c.policy = *policy;
  } else {
    std::uint32_t value = 0;
    const auto [end, ec] = std::from_chars(o.cache.data(), o.cache.data() + o.cache.size(), value);
    if (ec != std::errc{} || end != o.cache.data() + o.cache.size() || !power_of_two(value))
      throw Error("--cache", "expected off, on, auto or a power of two from 1 to 4096, got '" +
                                 printable(o.cache) + "'");
    c.policy = cache::CachePolicy::Auto;
    c.resolution = value;
  }
  const auto lookup = cache::parse_lookup_mode(o.cache_lookup);
  if (!lookup)
    throw Error("--cache-lookup",
                "expected direction, tau or march, got '" + printable(o.cache_lookup) + "'");
  c.lookup = *lookup;
  if (!(o.cache_tau_deg > 0.0f && o.cache_tau_deg < 90.0f))
    throw Error("--cache-tau", "must lie in (0, 90) degrees");
  c.tau_deg = o.cache_tau_deg;
  if (o.cache_resolution != 0) {
    if (!power_of_two(o.cache_resolution))
      throw Error("--cache-resolution", "expected a power of two from 1 to 4096, got " +
                                            std::to_string(o.cache_resolution));
    c.resolution = o.cache_resolution;
  }
  c.fill_budget = o.cache_fill;
  c.prefill = o.cache_prefill;
  c.fill_ahead = o.cache_fill_ahead;
  if (o.cache_samples < 1 || o.cache_samples > 65536)
    throw Error("--cache-samples", "must lie in 1 … 65536, got " + std::to_string(o.cache_samples));
  c.path_samples = o.cache_samples;
  if (o.cache_refresh < 1 || o.cache_refresh > 65536)
    throw Error("--cache-refresh", "must lie in 1 … 65536, got " + std::to_string(o.cache_refresh));
  c.path_refresh = o.cache_refresh;
  if (o.cache_irradiance != "on" && o.cache_irradiance != "off")
    throw Error("--cache-irradiance",
                "expected on or off, got '" + printable(o.cache_irradiance) + "'");
  c.path_irradiance = o.cache_irradiance == "on";
  if (o.cache_serve != "on" && o.cache_serve != "off")
    throw Error("--cache-serve", "expected on or off, got '" + printable(o.cache_serve) + "'");
  c.path_serve = o.cache_serve == "on";
  if (!(o.max_error_db > 0.0 && o.max_error_db < 200.0))
    throw Error("--max-error-db", "must lie in (0, 200)");
  c.max_error_db = o.max_error_db;
  return c;
}

/// A path or other user text echoed in normal output: control bytes escaped so it stays on its
/// line, but not cut (the user wants to see which file it was).
std::string shown(const std::string& text) { return printable(text, 4096); }

} // namespace

std::uint64_t render_memory_bytes(std::uint32_t width, std::uint32_t height, std::uint32_t frames,
                                  std::optional<ImageFormat> out, bool stats, bool stochastic,
                                  bool accumulate, bool denoise) {
  const std::uint64_t pixels = std::uint64_t{width} * height;
  // The PNG: sRGB bytes (3 per pixel), then stb's filtered rows (3), its deflate output (at most
  // 9/8 of that, in a buffer grown by doubling) and the PNG it is copied into. The EXR is
  // streamed to the file a chunk of 16 scan lines at a time, through a few chunk-sized buffers.
  std::uint64_t writing = 0;
  if (out == ImageFormat::Png) writing = pixels * 14;
  if (out == ImageFormat::Exr) writing = std::uint64_t{16} * width * sizeof(vec3) * 4;
  const std::uint64_t per_frame = sizeof(FrameStats) + (stats ? 2048 : 0);
  // Accumulation: the double sum and the frame; denoising: the guides (albedo, normal, depth),
  // the noisy mean and two framebuffers for the filter's passes.
  std::uint64_t progressive = 0;
  if (stochastic && accumulate) progressive += sizeof(dvec3) + sizeof(vec3);
  if (stochastic && denoise) progressive += 2 * sizeof(vec3) + sizeof(float) + 3 * sizeof(vec3);
  return pixels * (sizeof(vec3) + progressive) + writing + std::uint64_t{frames} * per_frame +
         (std::uint64_t{64} << 20);
}

namespace {

/// `specula info` without a scene: what this machine can trace with.
int run_machine_info(bool as_json, std::ostream& out) {
  std::string why_no_device;
  const std::vector<VulkanDeviceEntry> devices = vulkan_devices(&why_no_device);
  const std::optional<std::string> auto_note = auto_cpu_reason();
  const std::string auto_pick = resolve_backend("auto");
  if (as_json) {
    nlohmann::json backends = nlohmann::json::array();
    for (const BackendInfo& b : specula::backends()) {
      nlohmann::json entry = {{"name", std::string(b.name)}, {"available", b.available}};
      if (!b.available) entry["reason"] = b.reason;
      backends.push_back(entry);
    }
    nlohmann::json list = nlohmann::json::array();
    for (const VulkanDeviceEntry& d : devices)
      list.push_back(
          {{"name", d.name}, {"type", d.type}, {"compute", d.compute}, {"chosen", d.chosen}});
    nlohmann::json j = {{"backends", backends}, {"auto", auto_pick}, {"vulkan_devices", list}};
    if (auto_note) j["auto_reason"] = *auto_note;
    if (!why_no_device.empty()) j["vulkan_unavailable"] = why_no_device;
    out << j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
    return 0;
  }
  out << "backends:\n";
  for (const BackendInfo& b : specula::backends())
    out << "  " << b.name << ": " << (b.available ? "available" : b.reason) << "\n";
  out << "auto:       " << auto_pick;
  if (auto_note) out << " (" << *auto_note << ")";
  out << "\nVulkan devices:" << (devices.empty() ? " none" : "") << "\n";
  for (const VulkanDeviceEntry& d : devices)
    out << "  " << (d.chosen ? "* " : "  ") << d.name << " (" << d.type
        << (d.compute ? "" : ", no compute queue") << ")" << (d.chosen ? " — chosen" : "") << "\n";
  if (!why_no_device.empty()) out << "  (none chosen: " << one_line(why_no_device) << ")\n";
  return 0;
}

/// The GPU side of a frame: the tracer's counters when it runs on a device.
GpuFrameStats gpu_frame_stats(const Tracer& tracer) {
  GpuFrameStats g;
  if (const std::optional<TracerDevice> d = tracer_device(tracer)) {
    g.present = true;
    g.rays = d->rays;
    g.resumed = d->resumed;
    g.cut = d->cut;
    g.dispatches = d->dispatches;
    g.gpu_ms = d->gpu_ms;
    g.stage_ms = d->stage_ms;
    g.submits = d->submits;
  }
  return g;
}

} // namespace

int run_info(const InfoOptions& options, std::ostream& out) {
  if (options.scene.empty()) return run_machine_info(options.json, out);
  Scene scene = load_scene(options.scene);
  const SceneSummary s = summarize(scene);
  if (options.json) {
    nlohmann::json j = {{"scene", options.scene},
                        {"entities", s.entities},
                        {"mesh_entities", s.mesh_entities},
                        {"unique_meshes", s.unique_meshes},
                        {"triangles", s.triangles},
                        {"materials", s.materials},
                        {"lights", s.lights},
                        {"emissive_meshes", s.emissive_meshes},
                        {"cameras", s.cameras},
                        {"reflective", s.reflective},
                        {"refractive", s.refractive},
                        {"ray_cache_cubes", s.ray_cache_cubes},
                        {"animated", s.animated},
                        {"settings",
                         {{"width", scene.settings.width},
                          {"height", scene.settings.height},
                          {"max_depth", scene.settings.max_depth}}}};
    if (!s.bounds.empty())
      j["bounds"] = {{"min", vec_json(s.bounds.min)}, {"max", vec_json(s.bounds.max)}};
    // Invalid UTF-8 in a path is replaced, not a reason to fail.
    out << j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
    return 0;
  }
  out << "scene:      " << shown(options.scene) << "\n"
      << "entities:   " << s.entities << " (" << s.mesh_entities << " with meshes, "
      << s.unique_meshes << " distinct meshes, " << s.animated << " animated)\n"
      << "triangles:  " << s.triangles << "\n"
      << "materials:  " << s.materials << " (" << s.reflective << " reflective, " << s.refractive
      << " refractive entities)\n"
      << "lights:     " << s.lights << " (+ " << s.emissive_meshes << " emissive meshes)\n"
      << "cameras:    " << s.cameras << "\n"
      << "ray caches: " << s.ray_cache_cubes << "\n"
      << "image:      " << scene.settings.width << "x" << scene.settings.height << "\n";
  if (s.bounds.empty()) {
    out << "bounds:     empty\n";
  } else {
    out << "bounds:     min (" << s.bounds.min.x << ", " << s.bounds.min.y << ", " << s.bounds.min.z
        << ") max (" << s.bounds.max.x << ", " << s.bounds.max.y << ", " << s.bounds.max.z << ")\n";
  }
  return 0;
}

int run_render(const RenderOptions& options, std::ostream& out, std::ostream* progress,
               bool progress_is_terminal, std::ostream* notes) {
  using Clock = std::chrono::steady_clock;
  // Validate everything the user gave before reporting what this build lacks, so a bad scene or
  // option is reported as such (exit 1) rather than hidden behind "not available" (exit 2).
  const cache::CacheSettings cache_settings = parse_cache(options);
  for (const auto& [name, value] :
       {std::pair{"--width", options.width}, std::pair{"--height", options.height}})
    if (value > kMaxImageSide)
      throw Error(name, "expected a whole number in [1 - " + std::to_string(kMaxImageSide) +
                            "], got " + std::to_string(value));
  if (options.frames < 1 || options.frames > kMaxFrames)
    throw Error("--frames", "expected a whole number in [1 - " + std::to_string(kMaxFrames) +
                                "], got " + std::to_string(options.frames));
  std::optional<TimeRange> time_range;
  if (!options.time.empty()) time_range = parse_time_range(options.time);
  const std::optional<TraceMode> mode = parse_trace_mode(options.mode);
  if (!mode) throw Error("--mode", "unknown mode '" + printable(options.mode) + "'");
  if (cache_settings.prefill && *mode == TraceMode::Path)
    throw Error("--cache-prefill", "path mode's cubes average path samples; prefill traces "
                                   "Whitted radiance from the centre and cannot fill them");
  if (cache_settings.fill_ahead != 0 && *mode == TraceMode::Path)
    throw Error("--cache-fill-ahead", "path mode's cubes average path samples; fill ahead "
                                      "traces Whitted radiance from the centre and cannot fill "
                                      "them");
  if (options.spp < 1 || options.spp > kMaxSpp)
    throw Error("--spp", "expected a whole number in [1 - " + std::to_string(kMaxSpp) + "], got " +
                             std::to_string(options.spp));
  if (options.shadow_samples < 1 || options.shadow_samples > kMaxShadowSamples)
    throw Error("--shadow-samples", "expected a whole number in [1 - " +
                                        std::to_string(kMaxShadowSamples) + "], got " +
                                        std::to_string(options.shadow_samples));
  const std::optional<LightSampling> sampling = parse_light_sampling(options.sampling);
  if (!sampling)
    throw Error("--sampling",
                "expected mis, bsdf or light, got '" + printable(options.sampling) + "'");
  if (options.accumulate != "on" && options.accumulate != "off")
    throw Error("--accumulate", "expected on or off, got '" + printable(options.accumulate) + "'");
  GpuTracerOptions gpu;
  if (options.gpu_execution == "wavefront")
    gpu.execution = GpuTracerOptions::Execution::wavefront;
  else if (options.gpu_execution == "single")
    gpu.execution = GpuTracerOptions::Execution::single_kernel;
  else
    throw Error("--gpu-execution",
                "expected wavefront or single, got '" + printable(options.gpu_execution) + "'");
  if (options.gpu_primary == "trace")
    gpu.primary = GpuTracerOptions::Primary::trace;
  else if (options.gpu_primary == "raster")
    gpu.primary = GpuTracerOptions::Primary::raster;
  else
    throw Error("--gpu-primary",
                "expected trace or raster, got '" + printable(options.gpu_primary) + "'");
  if (options.gpu_frames != "on" && options.gpu_frames != "off")
    throw Error("--gpu-frames", "expected on or off, got '" + printable(options.gpu_frames) + "'");
  gpu.device_frames = options.gpu_frames == "on";
  if (!(options.grid_density > 0.0f && options.grid_density <= 64.0f))
    throw Error("--grid-density", "expected cells per triangle in (0, 64], got " +
                                      shown_number(options.grid_density));
  gpu.grid_density = options.grid_density;
  const bool stochastic = stochastic_mode(*mode);
  if (options.denoise && !stochastic)
    throw Error("--denoise", "filters the noise of --mode path and shadow; mode '" + options.mode +
                                 "' has none");
  // The output paths too: a render of an hour must not end with "unsupported extension".
  std::optional<ImageFormat> out_format;
  if (!options.out.empty())
    out_format = check_image_output_path(options.out, {ImageFormat::Png, ImageFormat::Exr});
  const MemoryBudget budget = memory_budget(options.memory_limit, "--memory-limit");
  if (!is_backend_name(options.backend))
    (void)resolve_backend(options.backend); // throws the "unknown backend" error (exit 1)
  Scene scene = load_scene(options.scene);
  if (!time_range) time_range = scene_time_range(scene);

  RenderJob job;
  job.backend = options.backend;
  job.settings.mode = *mode;
  job.settings.max_depth = scene.settings.max_depth;
  job.settings.background = scene.settings.background;
  job.settings.threads = options.threads;
  const std::uint32_t width = options.width ? options.width : scene.settings.width;
  const std::uint32_t height = options.height ? options.height : scene.settings.height;
  job.settings.spp = options.spp;
  job.settings.shadow_samples = options.shadow_samples;
  job.settings.sampling = *sampling;
  job.settings.seed = options.seed;
  job.accumulate = options.accumulate == "on";
  if (options.denoise) job.denoise = DenoiseSettings{};
  const std::optional<DenoiseSettings> denoise = job.denoise;
  check_memory(render_memory_bytes(width, height, options.frames, out_format,
                                   !options.stats.empty(), stochastic, job.accumulate,
                                   options.denoise),
               budget, options.scene,
               "rendering " + std::to_string(options.frames) + " frame(s) of " +
                   std::to_string(width) + "x" + std::to_string(height));
  job.image = Framebuffer(width, height);
  job.cache = cache_settings;
  job.gpu = gpu;
  const SceneKind kind = scene_kind(scene.registry);
  // A device failing (a lost device, an allocation the device refused) is the backend's failure,
  // neither bad input nor a bug here: say which backend and device, and stop.
  std::string backend = resolve_backend(options.backend, kind);
  std::string device;
  const auto naming_device_failures = [&](const auto& step) {
    try {
      step();
    } catch (const std::exception& e) {
      if (!is_device_failure(e)) throw;
      throw BackendFailure("backend '" + backend + "'" + (device.empty() ? "" : " on " + device) +
                           " failed: " + one_line(e.what()));
    }
  };
  naming_device_failures([&] { prepare_rendering(scene.registry, std::move(job)); });
  backend = scene.registry.resource<RenderJob>().backend;
  const Tracer& tracer = *scene.registry.resource<ActiveTracer>().tracer;
  const std::optional<TracerDevice> tracer_dev = tracer_device(tracer);
  if (tracer_dev) device = tracer_dev->name + " (" + tracer_dev->type + ")";
  if (options.backend == "auto" && notes != nullptr)
    if (const std::optional<std::string> why = auto_cpu_reason(kind); why && !tracer_dev)
      *notes << "specula: note: --backend auto: " << *why << "\n";

  RunStats stats;
  stats.settings = {options.scene,
                    backend,
                    options.mode,
                    width,
                    height,
                    options.frames,
                    options.threads,
                    scene.settings.max_depth,
                    cache_settings.resolution};
  stats.settings.cache_policy = cache::cache_policy_name(cache_settings.policy);
  stats.settings.cache_lookup = cache::lookup_mode_name(cache_settings.lookup);
  stats.settings.cache_tau_deg = cache_settings.tau_deg;
  stats.settings.cache_fill_budget = cache_settings.fill_budget;
  stats.settings.cache_prefill = cache_settings.prefill;
  stats.settings.cache_fill_ahead = cache_settings.fill_ahead;
  stats.settings.cache_samples = cache_settings.path_samples;
  stats.settings.cache_refresh = cache_settings.path_refresh;
  stats.settings.cache_irradiance = cache_settings.path_irradiance;
  stats.settings.cache_serve = cache_settings.path_serve;
  stats.settings.max_error_db = cache_settings.max_error_db;
  stats.settings.spp = options.spp;
  stats.settings.shadow_samples = options.shadow_samples;
  stats.settings.sampling = light_sampling_name(*sampling);
  stats.settings.seed = options.seed;
  stats.settings.accumulate = options.accumulate == "on";
  if (denoise) {
    stats.settings.denoise = true;
    stats.settings.denoise_iterations = denoise->iterations;
    stats.settings.denoise_sigma_color = denoise->sigma_color;
    stats.settings.denoise_sigma_normal = denoise->sigma_normal;
    stats.settings.denoise_sigma_depth = denoise->sigma_depth;
    stats.settings.denoise_sigma_variance = denoise->sigma_variance;
  }
  if (tracer_dev) {
    stats.settings.gpu_device = tracer_dev->name;
    stats.settings.gpu_device_type = tracer_dev->type;
    stats.settings.gpu_execution = tracer_dev->execution;
    stats.settings.gpu_primary = tracer_dev->primary;
    stats.settings.gpu_device_frames = tracer_dev->device_frames;
    stats.settings.grid_density = gpu.grid_density;
  }
  Schedule schedule;
  const Clock::time_point start = Clock::now();
  bool progress_shown = false;
  for (std::uint32_t f = 0; f < options.frames; ++f) {
    // With a range, each tick advances to frame f's time (the first from 0 to T0).
    double dt = 1.0 / 60.0;
    if (time_range) {
      const double step =
          options.frames > 1 ? (time_range->t1 - time_range->t0) / double(options.frames - 1) : 0.0;
      dt = time_range->t0 + double(f) * step - schedule.last().time;
    }
    naming_device_failures([&] { schedule.tick(scene.registry, dt); });
    stats.frames.push_back(scene.registry.resource<RenderJob>().last);
    stats.frames.back().gpu = gpu_frame_stats(tracer);
    const double elapsed = std::chrono::duration<double>(Clock::now() - start).count();
    if (progress != nullptr && progress_is_terminal && elapsed > options.progress_after_s &&
        f + 1 < options.frames) {
      const double rate = double(f + 1) / elapsed;
      char line[160];
      std::snprintf(line, sizeof line, "\r  frame %u/%u, %.1f frames/s, %.0f s left   ", f + 1,
                    options.frames, rate, double(options.frames - f - 1) / rate);
      *progress << line << std::flush;
      progress_shown = true;
    }
  }
  if (progress_shown) *progress << "\r" << std::string(60, ' ') << "\r" << std::flush;
  stats.settings.time0 = stats.frames.front().time;
  stats.settings.time1 = stats.frames.back().time;
  const RenderJob& done = scene.registry.resource<RenderJob>();
  if (!options.out.empty()) write_image(done.image, options.out);
  if (!options.stats.empty()) write_stats_file(stats, options.stats);

  std::vector<double> ms, trace_ms;
  for (const FrameStats& f : stats.frames) {
    ms.push_back(f.ms);
    trace_ms.push_back(f.trace_ms);
  }
  const double frame_ms = median(ms);
  const double trace = median(trace_ms);
  const FrameStats& last = stats.frames.back();
  out << shown(options.scene) << ": " << width << "x" << height << " " << options.mode << " on "
      << backend << (options.backend == "auto" ? " (auto)" : "") << ", " << options.frames
      << " frame(s)\n"
      << "  frame ms: median " << frame_ms << " (tracing " << trace << "), " << 1000.0 / frame_ms
      << " frames/s\n"
      << "  rays per frame: " << last.rays.total() << " (";
  const char* sep = "";
  for (const RayKind k :
       {RayKind::Primary, RayKind::Shadow, RayKind::Reflection, RayKind::Refraction}) {
    out << sep << ray_kind_name(k) << " " << last.rays[k];
    sep = ", ";
  }
  out << "), " << (trace > 0.0 ? double(last.rays.total()) / (trace * 1e3) : 0.0)
      << " Mrays/s of tracing time\n";
  {
    // Medians per system over the run: where a frame's time goes, the acceleration update split
    // by step, and what the last update did to the triangles (frame-to-frame coherence).
    const auto med = [&](double SystemTimes::*field) {
      std::vector<double> v;
      for (const FrameStats& f : stats.frames) v.push_back(f.systems.*field);
      return median(v);
    };
    const auto med_accel = [&](double AccelStats::*field) {
      std::vector<double> v;
      for (const FrameStats& f : stats.frames) v.push_back(f.accel.*field);
      return median(v);
    };
    const double accel_ms = med(&SystemTimes::acceleration_ms);
    out << "  systems ms (median): animation " << med(&SystemTimes::animation_ms) << ", transform "
        << med(&SystemTimes::transform_ms) << ", scene layer " << med(&SystemTimes::scene_layer_ms)
        << ", acceleration " << accel_ms << " (build "
        << med_accel(&AccelStats::static_build_ms) + med_accel(&AccelStats::blas_build_ms)
        << ", refit " << med_accel(&AccelStats::refit_ms) << ", restructure "
        << med_accel(&AccelStats::restructure_ms) << ", top level "
        << med_accel(&AccelStats::top_build_ms) << "; " << 100.0 * accel_ms / frame_ms
        << "% of the frame), cache invalidation " << med(&SystemTimes::cache_invalidation_ms)
        << ", render " << med(&SystemTimes::render_ms) << "\n"
        << "  last frame's triangles: " << last.accel.triangles_rebuilt << " rebuilt, "
        << last.accel.triangles_refit << " refit, " << last.accel.triangles_untouched
        << " untouched\n";
  }
  if (tracer_dev) {
    const GpuFrameStats& g = last.gpu;
    out << "  device: " << device << ", " << tracer_dev->execution << ", device frames "
        << (tracer_dev->device_frames ? "on" : "off") << "; last frame " << g.rays << " GPU rays, "
        << g.dispatches << " dispatches, " << g.submits << " submits, " << g.resumed << " resumed, "
        << g.cut << " cut, " << g.gpu_ms << " GPU ms";
    if (g.stage_ms != GpuStageTimes{}) {
      out << " (";
      for (int k = 0; k < kGpuStageCount; ++k)
        out << (k > 0 ? ", " : "") << gpu_stage_name(GpuStage(k)) << " "
            << g.stage_ms[std::size_t(k)];
      out << ")";
    }
    out << "\n";
  }
  if (cache_settings.policy != cache::CachePolicy::Off) {
    const CacheCounts& c = last.cache;
    out << "  cache: " << c.lookups << " lookups, " << c.hits << " served ("
        << (c.lookups > 0 ? 100.0 * double(c.hits) / double(c.lookups) : 0.0) << "%), " << c.valid
        << "/" << c.texels << " texels valid, " << c.memory_bytes / 1024 << " KiB\n";
    for (const CubeReport& r : c.cubes)
      out << "    cube of entity " << r.entity << " (" << r.resolution << "²): " << r.mode << " — "
          << r.reason << "\n";
  }
  if (stochastic) {
    std::uint64_t restarts = 0;
    std::vector<double> denoise_ms;
    for (const FrameStats& f : stats.frames) {
      restarts += f.accumulation_restarted ? 1 : 0;
      denoise_ms.push_back(f.denoise_ms);
    }
    out << "  samples per pixel: " << last.accumulated_samples << " in the image ("
        << (*mode == TraceMode::Path ? options.spp : options.shadow_samples) << " per frame, "
        << (options.accumulate == "on" ? "accumulated" : "not accumulated") << ", " << restarts
        << " restart(s)), " << options.sampling << " sampling, seed " << options.seed << "\n";
    if (options.denoise)
      out << "  denoised: à-trous, " << denoise->iterations << " levels, median "
          << median(denoise_ms) << " ms per frame\n";
  }
  if (last.rays.dropped > 0)
    out << "  dropped rays: " << last.rays.dropped
        << " (the per-pixel ray budget; in device frames, a ray tree past its node slots)\n";
  if (last.rays.nonfinite > 0)
    out << "  non-finite samples: " << last.rays.nonfinite << " (Inf/NaN radiance, written as 0)\n";
  if (last.accel.hidden_instances > 0)
    out << "  hidden instances: " << last.accel.hidden_instances
        << " (degenerate transform or bounds, e.g. a scale of 0)\n";
  if (!options.out.empty()) out << "  image: " << shown(options.out) << "\n";
  if (!options.stats.empty()) out << "  stats: " << shown(options.stats) << "\n";
  return 0;
}

} // namespace specula::cli
