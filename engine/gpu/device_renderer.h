#pragma once
/// \file
/// Whole frames on the device: the streaming ray tracer's kernels (Purcell et al. 2002) — eye-ray
/// generation, traversal + intersection, shadow rays, shading that emits secondary rays with
/// weights (no recursion) — over the scene GpuScene holds, as a wavefront (one dispatch per stage,
/// ray queues between them) or as a single kernel (VulkanTracer's Execution).
///
/// GROUNDWORK STUB: supports nothing yet (VulkanTracer then runs the CPU integrators over GPU
/// traversal).

#include "specula/gpu/gpu_scene.h"
#include "specula/gpu/vk_context.h"

namespace specula {
class SceneLayer;
class Framebuffer;
struct Camera;
struct TraceSettings;
struct FrameStats;
} // namespace specula

namespace specula::gpu {

enum class Execution : std::uint8_t;
struct GpuTraceCounters;

class DeviceRenderer {
public:
  DeviceRenderer(Context& context, const GpuScene& scene, Execution execution);
  ~DeviceRenderer();
  DeviceRenderer(const DeviceRenderer&) = delete;
  DeviceRenderer& operator=(const DeviceRenderer&) = delete;

  /// Whether these settings run on the device (modes with kernels, no hook, no guides).
  [[nodiscard]] bool supports(const TraceSettings& settings, bool has_hook, bool has_guides) const;
  /// Renders one frame into `out`; `counters` gets the frame's ray counts and GPU time.
  void render(const SceneLayer& layer, const Camera& camera, const TraceSettings& settings,
              Framebuffer& out, FrameStats& stats, GpuTraceCounters& counters);

private:
  Context& context_;
  const GpuScene& scene_;
  Execution execution_;
};

} // namespace specula::gpu
