#pragma once
/// \file
/// The schedule: the one place that knows the order of systems in a frame.

#include "specula/ecs/registry.h"
#include "specula/systems/frame_context.h"

#include <string_view>
#include <vector>

namespace specula {

/// Runs the frame's systems in a fixed order on each tick:
///   1. animation_system  (Animation → Transform, Mesh deformations; CameraPath → Camera)
///   2. transform_system  (Transform/Parent → WorldTransform, moved flags)
///   3. acceleration_system (moved/deformed entities → acceleration structures)
///   4. render_system     (the frame, on the backend chosen by prepare_rendering)
/// Cache invalidation will sit between 3 and 4. Stages 3–4 do nothing until a backend is prepared.
class Schedule {
public:
  /// Advances time by dt seconds and runs every system once. Returns the context it ran with.
  FrameContext tick(ecs::Registry& registry, double dt);

  /// The systems' names in run order (for logs, the editor and tests).
  [[nodiscard]] static std::vector<std::string_view> system_names();

  [[nodiscard]] const FrameContext& last() const { return ctx_; }

private:
  FrameContext ctx_;
};

} // namespace specula
