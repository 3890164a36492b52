#pragma once
/// \file
/// The schedule: the one place that knows the order of systems in a frame.

#include "specula/ecs/registry.h"
#include "specula/systems/frame_context.h"

#include <string_view>
#include <vector>

namespace specula {

/// Wall-clock time of the latest tick, whole and per system (in system_names() order): a
/// registry resource the schedule writes after every tick.
struct FrameTimings {
  double ms = 0.0;
  std::vector<double> system_ms;
};

/// Runs the frame's systems in a fixed order on each tick:
///   1. animation_system    (Animation → Transform, Mesh deformations; CameraPath → Camera)
///   2. transform_system    (Transform/Parent → WorldTransform, moved flags, TransformChanges)
///   3. scene_layer_system  (moved/deformed/added entities → the SceneLayer's tables and delta)
///   4. acceleration_system (the delta → the active tracer's structures)
///   5. cache_invalidation_system (what moved → outdated ray-cache texels; prefill)
///   6. render_system       (the frame, on the tracer chosen by prepare_rendering)
/// Stages 3–6 do nothing until rendering is prepared (5 also needs caching on).
/// After the systems it records FrameTimings, and in RenderJob::last the whole tick's time (ms),
/// each system's (systems) and the scene time the frame shows (time).
class Schedule {
public:
  /// Advances time by dt seconds and runs every system once. Returns the context it ran with.
  FrameContext tick(ecs::Registry& registry, double dt);

  /// The systems' names in run order (for logs, the editor, stats and tests).
  [[nodiscard]] static std::vector<std::string_view> system_names();

  [[nodiscard]] const FrameContext& last() const { return ctx_; }

private:
  FrameContext ctx_;
};

} // namespace specula
