#pragma once
#include "specula/ecs/registry.h"
#include "specula/systems/frame_context.h"

namespace specula {

/// Propagates the Transform/Parent hierarchy into WorldTransform, parents first, and flags
/// (WorldTransform::moved, moved_tick = ctx.tick) exactly the entities whose world transform
/// changed in this tick, including children of moved parents. Throws specula::Error on stale
/// parents or cycles.
void transform_system(ecs::Registry& registry, const FrameContext& ctx);

} // namespace specula
