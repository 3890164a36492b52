#pragma once
/// \file
/// The one place that maps a backend name to a tracer. Backends are chosen once, at start-up, by
/// name or by capability (`auto`); nothing else in the engine names a backend type.

#include "specula/ecs/registry.h"
#include "specula/trace/stats.h"
#include "specula/trace/tracer.h"

#include <cstdint>
#include <exception>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace specula {

class Framebuffer;
namespace gpu {
class Context;
struct DeviceFrame;
} // namespace gpu

struct BackendInfo {
  std::string_view name;
  bool available = false; ///< in this build and usable on this machine
  std::string reason;     ///< why not, when not available
  /// Whether rays through shared edges and vertices of closed meshes never slip between the
  /// triangles (a watertight ray/triangle test and conservative traversal). Embree 3's robust
  /// mode comes close but is not: the conformance suite measures how close
  /// (docs/design/watertightness.md).
  bool watertight = false;
};

/// Every backend name `--backend` accepts besides `auto`, in the order `auto` prefers them
/// (a real GPU first, then the CPU backends), with their availability.
[[nodiscard]] std::vector<BackendInfo> backends();

/// The names of backends(), in its order, without finding out which are available (that creates
/// a Vulkan instance, which loads every installed driver: a tenth of a second per process).
[[nodiscard]] std::span<const std::string_view> backend_names();

/// The entry of backends() with this name; throws specula::Error for a name no build knows.
[[nodiscard]] BackendInfo backend_info(std::string_view name);

/// Whether `name` is `auto` or a backend name any build knows (available here or not).
[[nodiscard]] bool is_backend_name(std::string_view name);

/// What a scene asks of the acceleration structures, for `auto`'s choice between CPU backends:
/// only static geometry; rigid dynamic objects (hierarchical or free instances); deforming meshes.
enum class SceneKind : std::uint8_t { static_only, rigid_dynamic, deforming };
[[nodiscard]] const char* scene_kind_name(SceneKind kind);
/// The kind of the registry's scene, from its Mesh entities' Kinematics (inferred where absent)
/// and vertex animations.
[[nodiscard]] SceneKind scene_kind(ecs::Registry& registry);

/// The backend a request names: `auto` → the first available one of backends(), with the CPU
/// backends in the order measured fastest for the scene's kind (cpu_preference); any other name
/// → itself if available. Throws specula::Error for a name no build knows, UnavailableError for
/// a backend missing from this build or machine (or none at all for `auto`), saying why.
[[nodiscard]] std::string resolve_backend(std::string_view requested,
                                          SceneKind kind = SceneKind::static_only);

/// The CPU backends in the order `auto` tries them for a kind of scene: the faster first, as
/// measured by specula_bench (docs/PERFORMANCE.md, "Choosing between CPU backends").
[[nodiscard]] std::vector<std::string_view> cpu_preference(SceneKind kind);

/// Why `auto` picks a CPU backend for this kind of scene, in one line ("no Vulkan GPU: only
/// llvmpipe (software) ...; embree chosen"), or nullopt when it picks the Vulkan backend. What
/// `specula render --backend auto` prints, so a user never wonders why the GPU was not used.
[[nodiscard]] std::optional<std::string> auto_cpu_reason(SceneKind kind = SceneKind::static_only);

/// How the Vulkan backends run (gpu::VulkanOptions, spelled without naming the backend's types):
/// the CLI's --gpu-execution, --gpu-primary, --gpu-frames and --grid-density. CPU backends ignore it.
struct GpuTracerOptions {
  enum class Execution : std::uint8_t { wavefront, single_kernel };
  Execution execution = Execution::wavefront;
  /// Device frames' primary hits: traced, or rasterised (hybrid mode, --gpu-primary raster).
  enum class Primary : std::uint8_t { trace, raster };
  Primary primary = Primary::trace;
  /// Whole cast and Whitted frames on the device; false: CPU integrators over GPU traversal.
  bool device_frames = true;
  /// vulkan-grid's and native-grid's target cells per triangle of the static set.
  float grid_density = 4.0f;
  /// Count the Vulkan traversal's ray/triangle tests (TracerDevice::tests; slower).
  bool count_tests = false;
  /// A Vulkan device to render on instead of opening one: a window's (present::Window::context),
  /// so that its frames can be presented where they are (keep_frames_on_device).
  std::shared_ptr<gpu::Context> device;
};

struct TracerOptions {
  std::uint32_t packet_width = 16; ///< primary packet width: 1, 4, 8 or 16
  SceneKind kind = SceneKind::static_only;
  GpuTracerOptions gpu;
  /// Native backends: single rays through the 4-wide collapse of the static set's BVH
  /// (`native-bvh`) and of rigid meshes' BVHs (NativeOptions::wide_bvh). False: through the
  /// binary trees, hit for hit as the Vulkan device (tests comparing the two).
  bool native_wide_bvh = true;
};

/// A new tracer of the named backend (resolve_backend's rules, so `auto` works too). Throws
/// specula::Error for bad options (packet width; grid density outside (0, 64]).
[[nodiscard]] std::unique_ptr<Tracer> make_tracer(std::string_view name,
                                                  const TracerOptions& options);
/// As above with the given primary packet width (1, 4, 8 or 16) and default GPU options.
[[nodiscard]] std::unique_ptr<Tracer> make_tracer(std::string_view name,
                                                  std::uint32_t packet_width = 16,
                                                  SceneKind kind = SceneKind::static_only);

/// The device a tracer runs on and its counters, for tracers on a device (the Vulkan backends);
/// nullopt for CPU tracers. The factory is the one place that knows backend types, so systems
/// and the CLI ask here rather than cast.
struct TracerDevice {
  std::string name; ///< the device's name ("NVIDIA H100 80GB HBM3", "llvmpipe (LLVM ...)")
  std::string type; ///< "discrete GPU", "integrated GPU", "virtual GPU", "CPU (software)", "other"
  std::string execution; ///< "wavefront" or "single kernel"
  std::string primary;   ///< "trace" or "raster" (hybrid mode)
  bool device_frames = true;
  /// The tracer's counters after its latest frame or batch (gpu::GpuTraceCounters).
  std::uint64_t rays = 0;
  std::uint64_t resumed = 0;
  std::uint64_t cut = 0;
  std::uint64_t retraced = 0; ///< hybrid mode: primary rays traced after all
  std::uint64_t dispatches = 0;
  std::uint64_t steps = 0; ///< traversal steps of the latest batch of rays (not of device frames)
  std::uint64_t tests = 0; ///< its ray/triangle tests, with GpuTracerOptions::count_tests
  double gpu_ms = 0.0;
  GpuStageTimes stage_ms{};  ///< of gpu_ms, by stage (wavefront cast and Whitted device frames)
  std::uint64_t submits = 0; ///< device frames: submits waited for, uploads and read-backs included
};
[[nodiscard]] std::optional<TracerDevice> tracer_device(const Tracer& tracer);

/// Device frames (the Vulkan backends' cast and Whitted frames) stay on the device instead of
/// being read into the frame's image, which is then left as it was: a presenter on the same
/// device draws device_frame() where it is (present::Window::present), and read_back_frame copies
/// it to the host when the pixels are needed. Returns false (nothing changed) for tracers
/// without a device.
bool keep_frames_on_device(Tracer& tracer, bool keep);
/// The tracer's last frame while it is on the device only (null for every other tracer and
/// frame); valid until the tracer renders again.
[[nodiscard]] const gpu::DeviceFrame* device_frame(const Tracer& tracer);
/// Copies that frame into `out` (of its size); throws specula::Error when there is none.
void read_back_frame(const Tracer& tracer, Framebuffer& out);

/// Whether an exception is a tracer's device failing (gpu::GpuError: a Vulkan call failed, the
/// device was lost), as opposed to bad input (specula::Error), a missing feature
/// (UnavailableError) or a bug. The CLI reports it naming the backend and device (exit 3).
[[nodiscard]] bool is_device_failure(const std::exception& e);

/// Vulkan devices the loader reports, for `specula info`: name, type (TracerDevice::type's words),
/// whether it has a compute queue, and whether the backend would choose it (Context::create's
/// choice, SPECULA_VK_DEVICE included). `why_none` gets the reason when none would be chosen.
struct VulkanDeviceEntry {
  std::string name;
  std::string type;
  bool compute = false;
  bool chosen = false;
};
[[nodiscard]] std::vector<VulkanDeviceEntry> vulkan_devices(std::string* why_none = nullptr);

} // namespace specula
