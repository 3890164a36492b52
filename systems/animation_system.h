#pragma once
#include "specula/ecs/registry.h"
#include "specula/systems/frame_context.h"

namespace specula {

/// Advances every Animation by ctx.dt and writes the sampled tracks into the entity's Transform
/// (only the tracks it has) and, for vertex tracks, into Mesh::deformed_positions (and normal
/// tracks into Mesh::deformed_normals, cleared when there is none), stamping
/// deformed_tick = ctx.tick — only when the animation time differs from the one the positions
/// were sampled at, so a paused or finished animation causes no refits. Advances every CameraPath
/// and moves its entity's Camera.
void animation_system(ecs::Registry& registry, const FrameContext& ctx);

} // namespace specula
