#include "specula/systems/cache_invalidation_system.h"

#include "specula/cache/ray_cache.h"
#include "specula/render/render_job.h"
#include "specula/scene/scene.h"

namespace specula {

void cache_invalidation_system(ecs::Registry& registry, const FrameContext& /*ctx*/) {
  cache::RayCaches* caches = registry.try_resource<cache::RayCaches>();
  const SceneLayer* layer = registry.try_resource<SceneLayer>();
  if (caches == nullptr || !caches->store || layer == nullptr || layer->syncs() == 0) return;
  caches->store->invalidate(registry, *layer);
  const cache::CacheSettings& settings = caches->store->settings();
  if (!settings.prefill && settings.fill_ahead == 0) return;
  const ActiveTracer* active = registry.try_resource<ActiveTracer>();
  const RenderJob* job = registry.try_resource<RenderJob>();
  if (active == nullptr || !active->tracer || job == nullptr) return;
  if (settings.prefill) caches->store->prefill(*active->tracer, *layer, job->settings);
  if (settings.fill_ahead != 0) {
    // Fill ahead traces from where the view will look texels up (the reflection points of the
    // camera's position).
    std::optional<vec3> eye;
    if (const std::optional<Camera> camera = active_camera(registry)) eye = vec3(camera->position);
    caches->store->fill_ahead(*active->tracer, *layer, job->settings, eye);
  }
}

} // namespace specula
