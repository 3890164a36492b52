#pragma once
#include "specula/ecs/registry.h"
#include "specula/systems/frame_context.h"

namespace specula {

/// Traces the frame into the RenderJob's image on the job's backend, from the scene's active
/// camera (active_camera), with every light, and stores the frame's stats (time and ray counts)
/// in the job. Does nothing when no job was prepared. Throws specula::Error when there is no
/// camera.
void render_system(ecs::Registry& registry, const FrameContext& ctx);

} // namespace specula
