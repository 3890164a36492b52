#pragma once
#include "specula/ecs/registry.h"
#include "specula/systems/frame_context.h"

namespace specula {

/// Brings the chosen backend's acceleration structures up to date with this tick's meshes and
/// world transforms (only entities that changed cause work: see EmbreeAccel). Does nothing when
/// no backend was prepared (prepare_rendering).
void acceleration_system(ecs::Registry& registry, const FrameContext& ctx);

} // namespace specula
