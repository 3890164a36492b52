#include "specula/render/render_job.h"

#include "specula/cache/ray_cache.h"
#include "specula/core/error.h"
#include "specula/render/tracer_factory.h"
#include "specula/scene/scene.h"

#include <chrono>
#include <string>

namespace specula {

FrameStats render_job_frame(RenderJob& job, const Tracer& tracer, const SceneLayer& layer,
                            const Camera& camera) {
  if (!stochastic_mode(job.settings.mode))
    return render_frame(tracer, layer, camera, job.settings, job.image, job.hook.get());
  const std::uint32_t width = job.image.width();
  const std::uint32_t height = job.image.height();
  try {
    // The layer synced earlier in this tick: a non-empty delta means the scene changed.
    const Accumulation::Frame next = job.accumulation.begin(
        job.settings, camera, width, height, !layer.delta().empty(), job.accumulate);
    TraceSettings settings = job.settings;
    settings.sample_offset = next.sample_offset;
    // The frame goes where it is shown when nothing is averaged; the mean goes to the image
    // unless the denoiser writes the image from it.
    Framebuffer& mean = job.denoise ? job.noisy : job.image;
    Framebuffer& target = job.accumulate ? job.frame : mean;
    if (target.width() != width || target.height() != height) target = Framebuffer(width, height);
    FrameStats stats = render_frame(tracer, layer, camera, settings, target, job.hook.get(),
                                    job.denoise ? &job.guides : nullptr);
    job.accumulation.add(target, mean);
    if (job.denoise) {
      const auto start = std::chrono::steady_clock::now();
      DenoiseSettings denoise = *job.denoise;
      if (denoise.threads == 0) denoise.threads = job.settings.threads;
      // Each frame's pixels are one draw of the pixel's estimate: their spread over the
      // accumulated frames gives the variance of the mean (none while there is one frame, or
      // when frames are shown on their own).
      if (next.restarted || !job.accumulate) job.moments.reset(target.pixel_count());
      job.moments.add(target, job.guides);
      atrous_denoise(job.noisy, job.guides, denoise, job.image, job.moments.variance_of_mean());
      stats.denoise_ms = std::chrono::duration<double, std::milli>(
                             std::chrono::steady_clock::now() - start)
                             .count();
    }
    stats.accumulated_samples = job.accumulation.samples();
    stats.accumulation_restarted = next.restarted;
    return stats;
  } catch (...) {
    // A frame begun but never added would skew the mean: the next frame starts afresh.
    job.accumulation.reset();
    throw;
  }
}

void prepare_rendering(ecs::Registry& registry, RenderJob job) {
  if (job.settings.max_depth > kMaxTraceDepth)
    throw Error("render settings", "max depth must be at most " + std::to_string(kMaxTraceDepth) +
                                       ", got " + std::to_string(job.settings.max_depth));
  if (job.settings.tile_size == 0 || job.settings.tile_size > 1024)
    throw Error("render settings", "tile size must be 1 to 1024");
  if (job.settings.spp < 1 || job.settings.spp > kMaxSpp)
    throw Error("render settings", "spp must be 1 to " + std::to_string(kMaxSpp) + ", got " +
                                       std::to_string(job.settings.spp));
  if (job.settings.shadow_samples < 1 || job.settings.shadow_samples > kMaxShadowSamples)
    throw Error("render settings", "shadow samples must be 1 to " +
                                       std::to_string(kMaxShadowSamples) + ", got " +
                                       std::to_string(job.settings.shadow_samples));
  if (std::uint64_t{job.settings.sample_offset} + samples_per_frame(job.settings) >
      (std::uint64_t{1} << 32))
    throw Error("render settings", "sample offset " + std::to_string(job.settings.sample_offset) +
                                       " leaves less than one frame of samples in the sequences");
  if (job.denoise && !stochastic_mode(job.settings.mode))
    throw Error("render settings", std::string("the denoiser filters path and shadow modes' "
                                               "noise; mode '") +
                                       trace_mode_name(job.settings.mode) + "' has none");
  TracerOptions tracer_options;
  tracer_options.packet_width = job.packet_width;
  tracer_options.kind = scene_kind(registry);
  tracer_options.gpu = job.gpu;
  tracer_options.native_wide_bvh = job.native_wide_bvh;
  std::unique_ptr<Tracer> tracer = make_tracer(job.backend, tracer_options);
  job.backend = std::string(tracer->name());
  if (job.cache.policy != cache::CachePolicy::Off) {
    if (job.hook)
      throw Error("render settings", "ray-cache cubes and another radiance hook cannot share a job");
    if (job.cache.resolution != 0 &&
        (job.cache.resolution < 1 || job.cache.resolution > 4096 ||
         (job.cache.resolution & (job.cache.resolution - 1)) != 0))
      throw Error("render settings", "cache resolution must be a power of two up to 4096, got " +
                                         std::to_string(job.cache.resolution));
    if (!(job.cache.tau_deg > 0.0f && job.cache.tau_deg < 90.0f))
      throw Error("render settings", "cache tau must lie in (0, 90) degrees");
    auto store = std::make_shared<cache::RayCacheStore>(job.cache);
    registry.set_resource<cache::RayCaches>(cache::RayCaches{store});
    job.hook = store;
  }
  registry.set_resource<ActiveTracer>(ActiveTracer{std::move(tracer)});
  // A new layer: its first sync hands the new tracer the whole scene.
  registry.set_resource<SceneLayer>();
  registry.set_resource<RenderJob>(std::move(job));
}

} // namespace specula
