#pragma once
#include "specula/ecs/registry.h"
#include "specula/systems/frame_context.h"

namespace specula {

/// Traces the frame into the RenderJob's image with the active tracer, from the scene's active
/// camera (active_camera), over the scene layer's tables — in path and shadow modes accumulating
/// frames while the layer's delta, the camera and the settings stay unchanged, and denoising when
/// the job asks (render_job_frame) — and stores the frame's stats and trace time in the job
/// (RenderJob::last; the schedule adds the whole tick's time). Does nothing when no job was
/// prepared. Throws specula::Error when there is no camera.
void render_system(ecs::Registry& registry, const FrameContext& ctx);

} // namespace specula
