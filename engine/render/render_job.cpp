#include "specula/render/render_job.h"

#include "specula/cache/ray_cache.h"
#include "specula/core/error.h"
#include "specula/render/tracer_factory.h"
#include "specula/scene/scene.h"

#include <string>

namespace specula {

void prepare_rendering(ecs::Registry& registry, RenderJob job) {
  if (job.settings.max_depth > kMaxTraceDepth)
    throw Error("render settings", "max depth must be at most " + std::to_string(kMaxTraceDepth) +
                                       ", got " + std::to_string(job.settings.max_depth));
  if (job.settings.tile_size == 0 || job.settings.tile_size > 1024)
    throw Error("render settings", "tile size must be 1 to 1024");
  // A tile's shadow rays are one batch: the bound keeps it in memory (16² pixels × 4096 rays).
  if (job.settings.shadow_samples == 0 || job.settings.shadow_samples > kMaxShadowSamples)
    throw Error("render settings", "shadow samples must be 1 to " +
                                       std::to_string(kMaxShadowSamples) + ", got " +
                                       std::to_string(job.settings.shadow_samples));
  if (job.settings.mode == TraceMode::Path)
    throw UnavailableError(std::string("mode '") + trace_mode_name(job.settings.mode) +
                           "' is not available yet (it lands with the streaming ray tracer)");
  std::unique_ptr<Tracer> tracer =
      make_tracer(job.backend, job.packet_width, scene_kind(registry));
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
