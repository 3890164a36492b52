#pragma once
#include "specula/ecs/registry.h"
#include "specula/systems/frame_context.h"

namespace specula {

/// Applies the scene layer's delta to the active tracer's acceleration structures (only what
/// changed causes work: see Tracer::update). Does nothing when no rendering was prepared.
void acceleration_system(ecs::Registry& registry, const FrameContext& ctx);

} // namespace specula
