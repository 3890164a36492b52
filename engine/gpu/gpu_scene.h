#pragma once
/// \file
/// The scene on the device: the buffers shaders/include/trace.glsl reads at bindings
/// [0, kSceneBindings) of set 0, brought up to date from the scene layer's delta.
///
/// GROUNDWORK STUB: uploads the layer's flat pools as they are (positions, triangles, meshes,
/// instances) for trace.glsl's brute-force stub. The two-level BVH / grid version replaces the
/// implementation and keeps the interface.

#include "specula/gpu/vk_context.h"
#include "specula/shared/trace_layout.h"
#include "specula/trace/tracer.h"

#include <array>
#include <cstdint>
#include <span>

namespace specula {
class SceneLayer;
}

namespace specula::gpu {

/// The structure the static set is traced with on the device (dynamic instances always go
/// through a top-level BVH over per-mesh BVHs).
enum class GpuStructure : std::uint8_t { bvh, grid };

class GpuScene {
public:
  GpuScene(Context& context, GpuStructure structure);
  GpuScene(const GpuScene&) = delete;
  GpuScene& operator=(const GpuScene&) = delete;

  /// Applies the layer's latest delta; the first call uploads everything.
  const TracerUpdateStats& update(const SceneLayer& layer);
  [[nodiscard]] const TracerUpdateStats& last_update() const { return last_; }

  /// The buffers of bindings [0, kSceneBindings), in binding order.
  [[nodiscard]] std::span<const Buffer* const> bindings() const { return bindings_; }
  [[nodiscard]] GpuStructure structure() const { return structure_; }
  [[nodiscard]] Context& context() const { return context_; }

private:
  Context& context_;
  GpuStructure structure_;
  std::array<Buffer, kSceneBindings> buffers_;
  std::array<const Buffer*, kSceneBindings> bindings_{};
  TracerUpdateStats last_;
};

} // namespace specula::gpu
