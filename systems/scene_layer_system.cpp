#include "specula/systems/scene_layer_system.h"

#include "specula/render/scene_layer.h"

namespace specula {

void scene_layer_system(ecs::Registry& registry, const FrameContext& /*ctx*/) {
  if (SceneLayer* layer = registry.try_resource<SceneLayer>()) layer->sync(registry);
}

} // namespace specula
