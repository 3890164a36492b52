#include "specula/systems/render_system.h"

#include "specula/accel/embree/embree_backend.h"
#include "specula/core/error.h"
#include "specula/scene/scene.h"
#include "specula/trace/render_job.h"

#include <chrono>

namespace specula {

void render_system(ecs::Registry& registry, const FrameContext& /*ctx*/) {
  RenderJob* job = registry.try_resource<RenderJob>();
  if (job == nullptr) return;
  const std::optional<Camera> camera = active_camera(registry);
  if (!camera) throw Error("scene", "has no camera to render from");
  const std::vector<SceneLight> lights = gather_lights(registry);
  const auto start = std::chrono::steady_clock::now();
  FrameStats stats;
  switch (job->backend) {
  case BackendKind::Embree: {
    const EmbreeBackend backend(registry.resource<EmbreeAccel>(), job->packet_width);
    stats = render_frame(backend, *camera, lights, job->settings, job->image);
    break;
  }
  case BackendKind::Native:
  case BackendKind::Vulkan:
    break; // prepare_rendering refuses them
  }
  stats.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  job->last = stats;
  ++job->frames;
}

} // namespace specula
