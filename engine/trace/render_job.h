#pragma once
/// \file
/// The render job: a registry resource holding what render_system needs (backend choice, trace
/// settings, the image) and what it reports (the last frame's stats). Backends are chosen once,
/// when the job is prepared.

#include "specula/ecs/registry.h"
#include "specula/image/framebuffer.h"
#include "specula/trace/renderer.h"
#include "specula/trace/stats.h"

#include <cstdint>
#include <optional>
#include <string_view>

namespace specula {

enum class BackendKind { Embree, Native, Vulkan };
[[nodiscard]] std::optional<BackendKind> parse_backend(std::string_view name);
[[nodiscard]] const char* backend_name(BackendKind kind);

struct RenderJob {
  BackendKind backend = BackendKind::Embree;
  /// Primary-ray packet width (1, 4, 8, 16); 16 measured fastest here (docs/PERFORMANCE.md).
  std::uint32_t packet_width = 16;
  TraceSettings settings;
  Framebuffer image{1, 1};
  FrameStats last;
  std::uint64_t frames = 0;
};

/// Installs the job and the chosen backend's acceleration resource in the registry. Throws
/// UnavailableError for a backend this build does not have, specula::Error for bad settings
/// (packet width, depth, tile size).
void prepare_rendering(ecs::Registry& registry, RenderJob job);

} // namespace specula
