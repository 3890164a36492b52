#include "specula/systems/render_system.h"

#include "specula/core/error.h"
#include "specula/render/render_job.h"
#include "specula/scene/scene.h"

#include <chrono>

namespace specula {

void render_system(ecs::Registry& registry, const FrameContext& /*ctx*/) {
  RenderJob* job = registry.try_resource<RenderJob>();
  if (job == nullptr) return;
  const std::optional<Camera> camera = active_camera(registry);
  if (!camera) throw Error("scene", "has no camera to render from");
  const Tracer& tracer = *registry.resource<ActiveTracer>().tracer;
  const SceneLayer& layer = registry.resource<SceneLayer>();
  const auto start = std::chrono::steady_clock::now();
  FrameStats stats = render_job_frame(*job, tracer, layer, *camera);
  stats.trace_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  stats.accel = job->last.accel; // written by the acceleration system this tick
  if (job->hook) job->hook->report(stats.cache);
  job->last = stats;
  ++job->frames;
}

} // namespace specula
