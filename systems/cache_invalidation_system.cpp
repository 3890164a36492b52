#include "specula/systems/cache_invalidation_system.h"

#include "specula/cache/ray_cache.h"
#include "specula/render/render_job.h"

namespace specula {

void cache_invalidation_system(ecs::Registry& registry, const FrameContext& /*ctx*/) {
  cache::RayCaches* caches = registry.try_resource<cache::RayCaches>();
  const SceneLayer* layer = registry.try_resource<SceneLayer>();
  if (caches == nullptr || !caches->store || layer == nullptr || layer->syncs() == 0) return;
  caches->store->invalidate(registry, *layer);
  if (caches->store->settings().prefill) {
    const ActiveTracer* active = registry.try_resource<ActiveTracer>();
    const RenderJob* job = registry.try_resource<RenderJob>();
    if (active != nullptr && active->tracer && job != nullptr)
      caches->store->prefill(*active->tracer, *layer, job->settings);
  }
}

} // namespace specula
