#include "specula/render/tracer_factory.h"

#include "specula/core/error.h"
#include "specula/scene/components.h"
#include "specula/scene/kinematics_rules.h"

#include "specula/accel/native/native_tracer.h"

#if SPECULA_HAS_EMBREE
#include "specula/accel/embree/embree_tracer.h"
#endif
#if SPECULA_HAS_VULKAN
#include "specula/gpu/vulkan_tracer.h"
#endif

namespace specula {

namespace {

/// What the Vulkan loader offers, probed once per process (creating an instance costs
/// milliseconds): whether any device can run the kernels, and whether one is a real GPU.
struct VulkanProbe {
  bool device = false;
  bool gpu = false;
  std::string reason;
};

const VulkanProbe& vulkan_probe() {
  static const VulkanProbe probe = [] {
    VulkanProbe p;
#if SPECULA_HAS_VULKAN
    std::string why;
    for (const gpu::DeviceSummary& d : gpu::list_devices(&why)) {
      if (!d.compute) continue;
      p.device = true;
      if (d.type != VK_PHYSICAL_DEVICE_TYPE_CPU) p.gpu = true;
    }
    if (!p.device) p.reason = "unavailable: " + (why.empty() ? std::string("no Vulkan compute device") : why);
#else
    p.reason = "not in this build (configured with SPECULA_WITH_VULKAN=OFF)";
#endif
    return p;
  }();
  return probe;
}

} // namespace

std::vector<BackendInfo> backends() {
  std::vector<BackendInfo> list;
  // The order is auto's preference: a real GPU first (lavapipe, the software Vulkan device, is
  // slower than the CPU backends), then the CPU backends.
  const VulkanProbe& vk = vulkan_probe();
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
  return list;
}

BackendInfo backend_info(std::string_view name) {
  for (BackendInfo& b : backends())
    if (b.name == name) return std::move(b);
  throw Error("--backend", "unknown backend '" + std::string(name) + "'");
}

bool is_backend_name(std::string_view name) {
  if (name == "auto") return true;
  for (const BackendInfo& b : backends())
    if (b.name == name) return true;
  return false;
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
  // Measured with specula_bench (docs/PERFORMANCE.md §6): Embree is the fastest CPU backend on
  // static scenes (primary, shadow and reflection rays) and on both animated scenes, rigid and
  // deforming; of the native configurations the BVH over the static set beats the kd-tree on
  // each of them. Kept per kind so that a measurement that turns one around changes one line.
  switch (kind) {
  case SceneKind::static_only:
  case SceneKind::rigid_dynamic:
  case SceneKind::deforming:
  default:
    return {"embree", "native-bvh", "native"};
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

std::unique_ptr<Tracer> make_tracer(std::string_view name, std::uint32_t packet_width,
                                    SceneKind kind) {
  if (packet_width != 1 && packet_width != 4 && packet_width != 8 && packet_width != 16)
    throw Error("render settings",
                "packet width must be 1, 4, 8 or 16, got " + std::to_string(packet_width));
  const std::string backend = resolve_backend(name, kind);
#if SPECULA_HAS_EMBREE
  if (backend == "embree") return std::make_unique<EmbreeTracer>(packet_width);
#endif
#if SPECULA_HAS_VULKAN
  if (backend == "vulkan" || backend == "vulkan-grid") {
    gpu::VulkanOptions options;
    if (backend == "vulkan-grid") options.structure = gpu::GpuStructure::grid;
    return std::make_unique<gpu::VulkanTracer>(packet_width, options);
  }
#endif
  NativeOptions options;
  if (backend == "native-bvh") options.static_structure = StaticStructure::bvh;
  if (backend == "native-grid") options.static_structure = StaticStructure::grid;
  if (backend == "native" || backend == "native-bvh" || backend == "native-grid")
    return std::make_unique<NativeTracer>(packet_width, options);
  throw UnavailableError("backend '" + backend + "' has no tracer in this build");
}

} // namespace specula
