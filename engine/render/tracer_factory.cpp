#include "specula/render/tracer_factory.h"

#include "specula/core/error.h"
#include "specula/scene/components.h"
#include "specula/scene/kinematics_rules.h"

#include "specula/accel/native/native_tracer.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cstdlib>
#include <mutex>
#include <utility>

#if SPECULA_HAS_EMBREE
#include "specula/accel/embree/embree_tracer.h"
#endif
#if SPECULA_HAS_VULKAN
#include "specula/gpu/vulkan_tracer.h"
#endif

namespace specula {

namespace {

/// What the Vulkan loader offers, as the backend's Context::create would see it: whether a device
/// can run the kernels (named like SPECULA_VK_DEVICE when that is set), whether one is a real GPU,
/// and the software devices seen (for auto's message).
struct VulkanProbe {
  bool device = false;
  bool gpu = false;
  std::string reason;   ///< why no device, when none
  std::string software; ///< names of the CPU devices that would serve, comma-separated
};

#if SPECULA_HAS_VULKAN
std::string lower(std::string text) {
  for (char& c : text) c = char(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

const char* device_type_name(VkPhysicalDeviceType type) {
  gpu::DeviceInfo info;
  info.type = type;
  return info.type_name();
}
#endif

/// Probed once per process and SPECULA_VK_DEVICE value (creating an instance costs milliseconds;
/// tests change the variable between cases).
VulkanProbe vulkan_probe() {
  static std::mutex mutex;
  static std::optional<std::pair<std::string, VulkanProbe>> cached;
  const char* env = std::getenv("SPECULA_VK_DEVICE");
  const std::string wanted = env != nullptr ? env : "";
  const std::lock_guard<std::mutex> lock(mutex);
  if (cached && cached->first == wanted) return cached->second;
  VulkanProbe p;
#if SPECULA_HAS_VULKAN
  std::string why;
  std::string names;
  for (const gpu::DeviceSummary& d : gpu::list_devices(&why)) {
    names += (names.empty() ? "" : ", ") + d.name;
    if (!d.compute) continue;
    if (!wanted.empty() && lower(d.name).find(lower(wanted)) == std::string::npos) continue;
    p.device = true;
    if (d.type != VK_PHYSICAL_DEVICE_TYPE_CPU) {
      p.gpu = true;
    } else {
      p.software += (p.software.empty() ? "" : ", ") + d.name;
    }
  }
  if (!p.device) {
    if (!why.empty())
      p.reason = "unavailable: " + why;
    else if (!wanted.empty())
      p.reason = "unavailable: no Vulkan compute device named like '" + printable(wanted) +
                 "' (SPECULA_VK_DEVICE); devices: " + names;
    else
      p.reason = "unavailable: no Vulkan compute device";
  }
#else
  p.reason = "not in this build (configured with SPECULA_WITH_VULKAN=OFF)";
#endif
  cached.emplace(wanted, p);
  return p;
}

} // namespace

std::span<const std::string_view> backend_names() {
  // The order is auto's preference: a real GPU first (lavapipe, the software Vulkan device, is
  // slower than the CPU backends), then the CPU backends.
  static constexpr std::array<std::string_view, 6> names = {
      "vulkan", "vulkan-grid", "embree", "native", "native-bvh", "native-grid"};
  return names;
}

std::vector<BackendInfo> backends() {
  std::vector<BackendInfo> list;
  const VulkanProbe vk = vulkan_probe();
  list.push_back({"vulkan", vk.device, vk.reason, true});
  list.push_back({"vulkan-grid", vk.device, vk.reason, true});
#if SPECULA_HAS_EMBREE
  list.push_back({"embree", true, "", false});
#else
  list.push_back(
      {"embree", false, "not in this build (configured with SPECULA_WITH_EMBREE=OFF)", false});
#endif
  // Specula's own structures: the static set in a kd-tree (the default), a BVH or a grid.
  list.push_back({"native", true, "", true});
  list.push_back({"native-bvh", true, "", true});
  list.push_back({"native-grid", true, "", true});
  return list; // in backend_names()'s order (TracerFactory.BackendNamesAreThoseOfBackends)
}

BackendInfo backend_info(std::string_view name) {
  for (BackendInfo& b : backends())
    if (b.name == name) return std::move(b);
  throw Error("--backend", "unknown backend '" + std::string(name) + "'");
}

bool is_backend_name(std::string_view name) {
  if (name == "auto") return true;
  const std::span<const std::string_view> names = backend_names();
  return std::find(names.begin(), names.end(), name) != names.end();
}

const char* scene_kind_name(SceneKind kind) {
  switch (kind) {
  case SceneKind::rigid_dynamic:
    return "rigid dynamic";
  case SceneKind::deforming:
    return "deforming";
  default:
    return "static";
  }
}

SceneKind scene_kind(ecs::Registry& registry) {
  SceneKind kind = SceneKind::static_only;
  registry.view<Mesh>().each([&](ecs::Entity e, const Mesh& mesh) {
    const Animation* anim = registry.try_get<Animation>(e);
    if (!mesh.deformed_positions.empty() || (anim != nullptr && !anim->vertices.empty())) {
      kind = SceneKind::deforming;
      return;
    }
    const Kinematics* k = registry.try_get<Kinematics>(e);
    const Kinematics::Type type = k != nullptr ? k->type : inferred_kinematics(registry, e);
    if (type != Kinematics::Type::Static && kind == SceneKind::static_only)
      kind = SceneKind::rigid_dynamic;
  });
  return kind;
}

std::vector<std::string_view> cpu_preference(SceneKind kind) {
  // Measured with specula_bench and `specula render` (docs/PERFORMANCE.md §6): Embree is the
  // fastest CPU backend on static scenes (primary, shadow and reflection rays) and on both
  // animated scenes, rigid and deforming. Of the native configurations, on static scenes the BVH
  // with its 4-wide collapse for single rays (since 2026-11-28) beats the kd-tree on whole frames:
  // Cornell box 1.13-1.17x (Whitted) and 1.5x (path), 32 mirror spheres 1.25-1.3x, the heavy
  // variant 1.26-1.31x, area lights a tie (the kd-tree 0-5% ahead). On the animated scenes the two
  // tied on 2026-11-28 (kd-tree + BVH 0.95-1.01x BVH only); on 2026-11-29 the bench's two animated
  // scenes had kd-tree + BVH 0.88-0.98x, the three-class sample a tie (24.9-25.2 against
  // 25.0-25.3 ms a frame). The kd-tree stays first there, as the real-time ray tracer paper has it,
  // until a margin holds on the samples too. Kept per kind so that a measurement that turns one
  // around changes one line.
  switch (kind) {
  case SceneKind::static_only:
    return {"embree", "native-bvh", "native"};
  case SceneKind::rigid_dynamic:
  case SceneKind::deforming:
  default:
    return {"embree", "native", "native-bvh"};
  }
}

std::string resolve_backend(std::string_view requested, SceneKind kind) {
  const std::vector<BackendInfo> all = backends();
  const auto available = [&](std::string_view name) {
    for (const BackendInfo& b : all)
      if (b.name == name) return b.available;
    return false;
  };
  if (requested == "auto") {
    // A real GPU first (lavapipe, the software Vulkan device, is slower than the CPU backends).
    if (available("vulkan") && vulkan_probe().gpu) return "vulkan";
    for (const std::string_view name : cpu_preference(kind))
      if (available(name)) return std::string(name);
    throw UnavailableError("no tracing backend is available in this build");
  }
  for (const BackendInfo& b : all) {
    if (b.name != requested) continue;
    if (!b.available)
      throw UnavailableError("backend '" + std::string(requested) + "' is " + b.reason);
    return std::string(b.name);
  }
  std::string names = "auto";
  for (const BackendInfo& b : all) names += ", " + std::string(b.name);
  throw Error("--backend",
              "unknown backend '" + std::string(requested) + "' (expected one of " + names + ")");
}

std::optional<std::string> auto_cpu_reason(SceneKind kind) {
  const VulkanProbe vk = vulkan_probe();
  if (vk.device && vk.gpu) return std::nullopt;
  std::string why;
  if (vk.device)
    why = "no Vulkan GPU, only software Vulkan (" + vk.software + "), slower than the CPU backends";
  else
    why = "no Vulkan GPU (vulkan " + vk.reason + ")";
  std::string chosen;
  for (const std::string_view name : cpu_preference(kind))
    if (backend_info(name).available) {
      chosen = std::string(name);
      break;
    }
  if (chosen.empty()) return why;
  return why + "; using the CPU backend " + chosen + ", the fastest here for " +
         scene_kind_name(kind) + " scenes";
}

std::unique_ptr<Tracer> make_tracer(std::string_view name, const TracerOptions& options) {
  if (options.packet_width != 1 && options.packet_width != 4 && options.packet_width != 8 &&
      options.packet_width != 16)
    throw Error("render settings",
                "packet width must be 1, 4, 8 or 16, got " + std::to_string(options.packet_width));
  if (!(options.gpu.grid_density > 0.0f && options.gpu.grid_density <= 64.0f))
    throw Error("render settings", "grid density must lie in (0, 64] cells per triangle, got " +
                                       std::to_string(options.gpu.grid_density));
  const std::string backend = resolve_backend(name, options.kind);
  const std::uint32_t packet_width = options.packet_width;
#if SPECULA_HAS_EMBREE
  if (backend == "embree") return std::make_unique<EmbreeTracer>(packet_width);
#endif
#if SPECULA_HAS_VULKAN
  if (backend == "vulkan" || backend == "vulkan-grid") {
    gpu::VulkanOptions vk;
    if (backend == "vulkan-grid") vk.structure = gpu::GpuStructure::grid;
    vk.execution = options.gpu.execution == GpuTracerOptions::Execution::single_kernel
                       ? gpu::Execution::single_kernel
                       : gpu::Execution::wavefront;
    vk.primary = options.gpu.primary == GpuTracerOptions::Primary::raster
                     ? gpu::PrimaryVisibility::raster
                     : gpu::PrimaryVisibility::trace;
    vk.device_frames = options.gpu.device_frames;
    vk.grid_density = options.gpu.grid_density;
    vk.count_tests = options.gpu.count_tests;
    vk.device = options.gpu.device;
    auto tracer = std::make_unique<gpu::VulkanTracer>(packet_width, vk);
    // Test-only: lets the CLI's tests reach the device-loss path of a whole run (every submit
    // then fails as on a lost device); see tests/cli.
    if (const char* lose = std::getenv("SPECULA_VK_SIMULATE_DEVICE_LOSS");
        lose != nullptr && std::string(lose) == "1")
      tracer->context().simulate_device_loss();
    return tracer;
  }
#endif
  NativeOptions native;
  if (backend == "native-bvh") native.static_structure = StaticStructure::bvh;
  if (backend == "native-grid") native.static_structure = StaticStructure::grid;
  native.grid_density = options.gpu.grid_density;
  native.wide_bvh = options.native_wide_bvh;
  if (backend == "native" || backend == "native-bvh" || backend == "native-grid")
    return std::make_unique<NativeTracer>(packet_width, native);
  throw UnavailableError("backend '" + backend + "' has no tracer in this build");
}

std::unique_ptr<Tracer> make_tracer(std::string_view name, std::uint32_t packet_width,
                                    SceneKind kind) {
  TracerOptions options;
  options.packet_width = packet_width;
  options.kind = kind;
  return make_tracer(name, options);
}

bool keep_frames_on_device(Tracer& tracer, bool keep) {
#if SPECULA_HAS_VULKAN
  if (auto* vk = dynamic_cast<gpu::VulkanTracer*>(&tracer)) {
    vk->set_keep_frames_on_device(keep);
    return true;
  }
#else
  (void)tracer;
  (void)keep;
#endif
  return false;
}

const gpu::DeviceFrame* device_frame(const Tracer& tracer) {
#if SPECULA_HAS_VULKAN
  if (const auto* vk = dynamic_cast<const gpu::VulkanTracer*>(&tracer)) return vk->device_frame();
#else
  (void)tracer;
#endif
  return nullptr;
}

void read_back_frame(const Tracer& tracer, Framebuffer& out) {
#if SPECULA_HAS_VULKAN
  if (const auto* vk = dynamic_cast<const gpu::VulkanTracer*>(&tracer);
      vk != nullptr && vk->device_frame() != nullptr) {
    vk->read_back_frame(out);
    return;
  }
#else
  (void)out;
#endif
  throw Error(std::string("backend '") + std::string(tracer.name()) +
              "' has no frame on a device to read back");
}

std::optional<TracerDevice> tracer_device(const Tracer& tracer) {
#if SPECULA_HAS_VULKAN
  if (const auto* vk = dynamic_cast<const gpu::VulkanTracer*>(&tracer)) {
    TracerDevice d;
    d.name = vk->context().info().name;
    d.type = vk->context().info().type_name();
    d.execution =
        vk->options().execution == gpu::Execution::single_kernel ? "single kernel" : "wavefront";
    d.primary = vk->options().primary == gpu::PrimaryVisibility::raster ? "raster" : "trace";
    d.device_frames = vk->options().device_frames;
    const gpu::GpuTraceCounters& c = vk->counters();
    d.rays = c.rays;
    d.resumed = c.resumed;
    d.cut = c.cut;
    d.retraced = c.retraced;
    d.dispatches = c.dispatches;
    d.steps = c.steps;
    d.tests = c.tests;
    d.gpu_ms = c.gpu_ms;
    d.stage_ms = c.stage_ms;
    d.submits = c.submits;
    return d;
  }
#else
  (void)tracer;
#endif
  return std::nullopt;
}

bool is_device_failure(const std::exception& e) {
#if SPECULA_HAS_VULKAN
  return dynamic_cast<const gpu::GpuError*>(&e) != nullptr;
#else
  (void)e;
  return false;
#endif
}

std::vector<VulkanDeviceEntry> vulkan_devices(std::string* why_none) {
  std::vector<VulkanDeviceEntry> list;
#if SPECULA_HAS_VULKAN
  std::string why;
  for (const gpu::DeviceSummary& d : gpu::list_devices(&why))
    list.push_back({d.name, device_type_name(d.type), d.compute, false});
  // The device the backend would open: ask Context::create itself, so that this list and the
  // backend never disagree (SPECULA_VK_DEVICE, API version, preference order).
  try {
    const std::string chosen = gpu::Context::create()->info().name;
    for (VulkanDeviceEntry& e : list)
      if (e.name == chosen) {
        e.chosen = true;
        break;
      }
  } catch (const UnavailableError& e) {
    why = e.what();
  } catch (const gpu::GpuError& e) {
    why = e.what();
  }
  if (why_none != nullptr) *why_none = why;
#else
  if (why_none != nullptr)
    *why_none = "not in this build (configured with SPECULA_WITH_VULKAN=OFF)";
#endif
  return list;
}

} // namespace specula
