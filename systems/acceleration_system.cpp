#include "specula/systems/acceleration_system.h"

#include "specula/render/render_job.h"

#include <chrono>

namespace specula {

void acceleration_system(ecs::Registry& registry, const FrameContext& /*ctx*/) {
  ActiveTracer* active = registry.try_resource<ActiveTracer>();
  const SceneLayer* layer = registry.try_resource<SceneLayer>();
  if (active == nullptr || !active->tracer || layer == nullptr) return;
  const auto start = std::chrono::steady_clock::now();
  const TracerUpdateStats& u = active->tracer->update(*layer);
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  if (RenderJob* job = registry.try_resource<RenderJob>()) {
    // This frame's part of the stats; the render system keeps it when it writes the rest.
    AccelStats& a = job->last.accel;
    a.ms = ms;
    a.static_build_ms = u.static_build_ms;
    a.blas_build_ms = u.blas_build_ms;
    a.refit_ms = u.refit_ms;
    a.restructure_ms = u.restructure_ms;
    a.top_build_ms = u.top_build_ms;
    a.static_builds = u.static_builds;
    a.blas_builds = u.blas_builds;
    a.refits = u.blas_refits;
    a.restructures = u.blas_restructures;
    a.hidden_instances = u.hidden_instances;
    a.triangles_rebuilt = u.triangles_rebuilt;
    a.triangles_refit = u.triangles_refit;
    // A shared mesh built once for several instances counts once but is held per instance.
    const std::uint64_t touched = u.triangles_rebuilt + u.triangles_refit;
    a.triangles_untouched = u.triangles > touched ? u.triangles - touched : 0;
  }
}

} // namespace specula
