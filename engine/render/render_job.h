#pragma once
/// \file
/// The render job: registry resources holding what the scene-layer, acceleration and render
/// systems need (the scene layer, the tracer chosen once at start-up, trace settings, the image)
/// and what they report (the last frame's stats).

#include "specula/cache/cache_settings.h"
#include "specula/ecs/registry.h"
#include "specula/image/framebuffer.h"
#include "specula/render/scene_layer.h"
#include "specula/trace/radiance_hook.h"
#include "specula/trace/render_frame.h"
#include "specula/trace/stats.h"
#include "specula/trace/tracer.h"

#include <cstdint>
#include <memory>
#include <string>

namespace specula {

struct RenderJob {
  /// The backend asked for (`auto` or a name, see render/tracer_factory.h); prepare_rendering
  /// replaces it with the one chosen.
  std::string backend = "auto";
  /// Primary-ray packet width (1, 4, 8, 16); 16 measured fastest here (docs/PERFORMANCE.md).
  std::uint32_t packet_width = 16;
  TraceSettings settings;
  Framebuffer image{1, 1};
  /// Ray-cache cubes: with a policy other than off, prepare_rendering creates the cache store
  /// (the cache::RayCaches resource) and makes it the hook.
  cache::CacheSettings cache;
  /// Receives the radiance of every leaving ray (none: integrators skip that bookkeeping).
  std::shared_ptr<RadianceHook> hook;
  /// The latest frame: ms is the whole tick (set by the schedule), trace_ms the render system's.
  FrameStats last;
  std::uint64_t frames = 0;
};

/// The tracer the job renders with (a resource, so systems reach it without naming its type).
struct ActiveTracer {
  std::unique_ptr<Tracer> tracer;
};

/// Checks the job's settings, creates its tracer through the factory and installs the job, the
/// tracer and a SceneLayer in the registry; the schedule's scene-layer, acceleration and render
/// systems then run on every tick. Throws UnavailableError for a backend or mode this build or
/// machine does not have, specula::Error for bad settings (packet width, tile size, a depth above
/// kMaxTraceDepth, the limit every scene loader applies too).
void prepare_rendering(ecs::Registry& registry, RenderJob job);

} // namespace specula
