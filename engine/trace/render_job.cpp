#include "specula/trace/render_job.h"

#include "specula/accel/embree/embree_accel.h"
#include "specula/core/error.h"

#include <string>

namespace specula {

std::optional<BackendKind> parse_backend(std::string_view name) {
  if (name == "embree") return BackendKind::Embree;
  if (name == "native") return BackendKind::Native;
  if (name == "vulkan") return BackendKind::Vulkan;
  return std::nullopt;
}

const char* backend_name(BackendKind kind) {
  switch (kind) {
  case BackendKind::Embree: return "embree";
  case BackendKind::Native: return "native";
  case BackendKind::Vulkan: return "vulkan";
  }
  return "unknown";
}

void prepare_rendering(ecs::Registry& registry, RenderJob job) {
  const std::uint32_t w = job.packet_width;
  if (w != 1 && w != 4 && w != 8 && w != 16)
    throw Error("render settings", "packet width must be 1, 4, 8 or 16, got " + std::to_string(w));
  if (job.settings.max_depth > 32)
    throw Error("render settings", "max depth must be at most 32, got " + std::to_string(job.settings.max_depth));
  if (job.settings.tile_size == 0 || job.settings.tile_size > 1024)
    throw Error("render settings", "tile size must be 1 to 1024");
  if (job.settings.mode == TraceMode::Path || job.settings.mode == TraceMode::Shadow)
    throw UnavailableError(std::string("mode '") + trace_mode_name(job.settings.mode) +
                           "' is not available yet (it lands with the streaming ray tracer)");
  switch (job.backend) {
  case BackendKind::Embree:
    if (registry.try_resource<EmbreeAccel>() == nullptr) registry.set_resource<EmbreeAccel>();
    break;
  case BackendKind::Native:
  case BackendKind::Vulkan:
    throw UnavailableError(std::string("backend '") + backend_name(job.backend) +
                           "' is not available yet (use --backend embree)");
  }
  registry.set_resource<RenderJob>(std::move(job));
}

} // namespace specula
