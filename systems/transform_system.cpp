#include "specula/systems/transform_system.h"

#include "specula/scene/hierarchy.h"

namespace specula {

void transform_system(ecs::Registry& registry, const FrameContext& ctx) {
  update_world_transforms(registry, ctx.tick);
}

} // namespace specula
