#include "specula/systems/acceleration_system.h"

#include "specula/accel/embree/embree_accel.h"

namespace specula {

void acceleration_system(ecs::Registry& registry, const FrameContext& /*ctx*/) {
  if (EmbreeAccel* accel = registry.try_resource<EmbreeAccel>()) accel->update(registry);
}

} // namespace specula
