#pragma once
/// \file
/// The Vulkan backend (`--backend vulkan`, `vulkan-grid`): Specula's own structures on the device
/// (GpuScene), rays traced by compute kernels. Two ways to use it, both kept:
///   - as a Tracer: intersect / occluded / intersect_camera upload a batch, dispatch
///     trace_rays.comp and read the hits back, so every CPU integrator (cast, Whitted, path,
///     shadow, the cache hook) runs over GPU traversal;
///   - whole frames on the device (render_frame_on_device): the streaming kernels — eye rays,
///     traversal + intersection, shadow rays, shading that emits secondary rays with weights —
///     either as a wavefront (one dispatch per stage, ray queues between them) or as one kernel
///     (VulkanOptions::execution), for the modes they cover.
/// Loops are bounded for lavapipe (PLATFORM-NOTES): a ray that uses up its per-dispatch traversal
/// budget is resumed in a further dispatch, and rays left pending (a driver cut) are counted.

#include "specula/gpu/device_renderer.h"
#include "specula/gpu/gpu_scene.h"
#include "specula/gpu/raster_primary.h"
#include "specula/gpu/vk_context.h"
#include "specula/shared/trace_layout.h"
#include "specula/trace/stats.h"
#include "specula/trace/tracer.h"

#include <cstdint>
#include <memory>
#include <string>

namespace specula::gpu {

/// How whole frames run on the device.
enum class Execution : std::uint8_t {
  wavefront,     ///< separate dispatches per stage with ray queues (the multi-pass way)
  single_kernel, ///< one kernel per pixel, bounces in a loop (the branching way)
};

struct VulkanOptions {
  GpuStructure structure = GpuStructure::bvh;
  Execution execution = Execution::wavefront;
  /// Device frames' primary hits: traced, or rasterised (hybrid mode).
  PrimaryVisibility primary = PrimaryVisibility::trace;
  /// Grid resolution: target cells per triangle of the static set (accel::GridBuildOptions).
  float grid_density = 4.0f;
  /// Traversal steps (nodes, triangles, cells, pops) a ray may take per dispatch of
  /// trace_rays.comp before it is saved and resumed in the next. Lavapipe ends every loop of a
  /// SIMD vector of 8 after 65,535 iterations per dispatch (all loops together), and each walk
  /// step counts twice there: measured on a one-cell grid of 327,680 triangles, budgets up to
  /// 32,700 finish (resumed) and 32,768 are cut. 16,384 leaves half of that as margin for the
  /// kernel's other loops (restoring and saving the stack, the static hit's binary search) and
  /// still resumes almost no ray (the bunny's longest walks take a few hundred steps).
  std::uint32_t traversal_budget = 16384;
  /// Render cast and Whitted frames with the streaming kernels; false: the CPU integrators over
  /// GPU traversal (every mode then).
  bool device_frames = true;
  /// Count ray/triangle tests in trace_rays.comp (GpuTraceCounters::tests; costs an atomic per
  /// ray). Traversal steps are always counted.
  bool count_tests = false;
  /// How to open the device when `device` is null.
  Context::Options context;
  /// A device to share instead (a window's: present::Window::context()), so that device frames
  /// can be presented where they are (set_keep_frames_on_device).
  std::shared_ptr<Context> device;
};

/// Counters of the latest batch or frame (tests assert cut == 0).
struct GpuTraceCounters {
  std::uint64_t rays = 0;
  std::uint64_t resumed = 0;    ///< rays that used up a dispatch's budget and were resumed
  std::uint64_t cut = 0;        ///< rays the driver cut off (status still pending): must be 0
  std::uint64_t retraced = 0;   ///< hybrid mode: primary rays traced after all (frame_visibility)
  std::uint64_t restarted = 0;  ///< device frames: resumed rays that found the state pool full
  std::uint64_t dispatches = 0; ///< traversal dispatches
  std::uint64_t steps = 0;      ///< traversal steps of trace_rays.comp (nodes, cells, tests, pops)
  std::uint64_t tests = 0;      ///< its ray/triangle tests (VulkanOptions::count_tests; else 0)
  double gpu_ms = 0.0;          ///< timestamp time of the dispatches
  GpuStageTimes stage_ms{};     ///< of gpu_ms, by stage (wavefront cast and Whitted frames)
  std::uint64_t submits = 0;    ///< device frames: submits waited for (uploads, read-backs)
};

class VulkanTracer final : public Tracer {
public:
  /// Opens a device (Context::create; or takes options.device) and the kernels. Throws
  /// specula::UnavailableError when there is no usable Vulkan device.
  explicit VulkanTracer(std::uint32_t packet_width = 8, VulkanOptions options = {});
  ~VulkanTracer() override;
  VulkanTracer(const VulkanTracer&) = delete;
  VulkanTracer& operator=(const VulkanTracer&) = delete;

  [[nodiscard]] std::string_view name() const override { return name_; }
  const TracerUpdateStats& update(const SceneLayer& layer) override;
  [[nodiscard]] const TracerUpdateStats& last_update() const override;
  void intersect(std::span<const Ray> rays, std::span<Hit> hits) const override;
  void occluded(std::span<const Ray> rays, std::span<std::uint8_t> occluded) const override;
  void intersect_camera(const CameraRays& camera, const PacketTile& tile,
                        PrimaryHits& hits) const override;
  bool render_frame_on_device(const SceneLayer& layer, const Camera& camera,
                              const TraceSettings& settings, Framebuffer& out, RadianceHook* hook,
                              GuideBuffers* guides, FrameStats& stats) const override;
  [[nodiscard]] std::uint32_t packet_width() const override { return packet_width_; }
  void set_packet_width(std::uint32_t width) override;

  [[nodiscard]] const VulkanOptions& options() const { return options_; }
  [[nodiscard]] Context& context() const { return *context_; }
  [[nodiscard]] const GpuScene& scene() const { return *scene_; }
  [[nodiscard]] const GpuTraceCounters& counters() const { return counters_; }
  /// The device-frame renderer (its latest frame's ray-cache figures, for tests).
  [[nodiscard]] const DeviceRenderer& renderer() const { return *renderer_; }

  /// Cast and Whitted device frames stay on the device, render_frame_on_device's `out` left as
  /// it was: a presenter on the same device draws device_frame() where it is, and
  /// read_back_frame() copies it to the host only when someone needs the pixels (a screenshot).
  /// Off by default (every frame read back into `out`).
  void set_keep_frames_on_device(bool keep);
  /// The last device frame while it is on the device only.
  [[nodiscard]] const DeviceFrame* device_frame() const;
  /// Copies the last device frame into `out` (of its size).
  void read_back_frame(Framebuffer& out) const;

private:
  struct Kernels;
  std::uint32_t packet_width_;
  VulkanOptions options_;
  std::string name_;
  std::shared_ptr<Context> context_;
  std::unique_ptr<GpuScene> scene_;
  std::unique_ptr<Kernels> kernels_;
  std::unique_ptr<DeviceRenderer> renderer_;
  mutable GpuTraceCounters counters_;

  /// Traces `rays` through trace_rays.comp (with kernels_->mutex held): closest hits into `hits`
  /// or occlusion into `occluded` (the other null).
  void trace_locked(std::span<const Ray> rays, Hit* hits, std::uint8_t* occluded) const;
};

} // namespace specula::gpu
