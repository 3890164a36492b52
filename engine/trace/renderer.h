#pragma once
/// \file
/// Frame rendering: the image is cut into square tiles handed out dynamically to worker threads
/// (TBB work stealing inside an arena of the requested size); each tile's primary rays are traced
/// as one coherent batch, then every pixel is shaded by the integrator of the chosen mode.
/// Pixels are independent and shading has no randomness, so the image is bit-identical whatever
/// the thread count.

#include "specula/image/framebuffer.h"
#include "specula/scene/components/camera.h"
#include "specula/trace/lights.h"
#include "specula/trace/stats.h"

#include <cstdint>
#include <optional>
#include <span>
#include <string_view>

namespace specula {

enum class TraceMode { Cast, Whitted, Path, Shadow };
[[nodiscard]] std::optional<TraceMode> parse_trace_mode(std::string_view name);
[[nodiscard]] const char* trace_mode_name(TraceMode mode);

struct TraceSettings {
  TraceMode mode = TraceMode::Whitted;
  /// Longest chain of reflection/refraction bounces after the primary hit.
  std::uint32_t max_depth = 5;
  /// A secondary ray whose weight (largest channel of its throughput) falls below this is not
  /// traced: its contribution cannot show in an 8-bit image (1/256).
  float min_weight = 1.0f / 256.0f;
  vec3 background{0.0f};
  std::uint32_t tile_size = 16;
  std::uint32_t threads = 0; ///< 0: every hardware thread
};

/// Renders one frame into `out` (its size is the image size) with the given backend (see
/// trace_backend.h; instantiated for each backend in its own .cpp). Returns ray counts; `ms` is
/// left for the caller to fill.
template <typename Backend>
FrameStats render_frame(const Backend& backend, const Camera& camera,
                        std::span<const SceneLight> lights, const TraceSettings& settings,
                        Framebuffer& out);

/// The primary-ray stage of render_frame alone (camera rays, coherent packets, hits resolved to
/// surfaces), for measuring the tracer's own overhead against its backend. Returns a checksum.
template <typename Backend>
std::uint64_t trace_primary_frame(const Backend& backend, const Camera& camera, std::uint32_t width,
                                  std::uint32_t height, const TraceSettings& settings);

} // namespace specula
