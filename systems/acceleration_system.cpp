#include "specula/systems/acceleration_system.h"

#include "specula/render/render_job.h"

namespace specula {

void acceleration_system(ecs::Registry& registry, const FrameContext& /*ctx*/) {
  ActiveTracer* active = registry.try_resource<ActiveTracer>();
  const SceneLayer* layer = registry.try_resource<SceneLayer>();
  if (active != nullptr && active->tracer && layer != nullptr) active->tracer->update(*layer);
}

} // namespace specula
