#pragma once
#include "specula/ecs/registry.h"
#include "specula/systems/frame_context.h"

namespace specula {

/// Turns this tick's changes (the transform system's moved entities, deformed meshes, added or
/// removed mesh entities, edited materials, lights) into the SceneLayer's tables and delta. Does
/// nothing when no rendering was prepared (no SceneLayer resource).
void scene_layer_system(ecs::Registry& registry, const FrameContext& ctx);

} // namespace specula
