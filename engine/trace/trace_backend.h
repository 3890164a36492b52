#pragma once
/// \file
/// What the renderer needs from a tracing backend. Backends are chosen once per run and trace
/// batches; the renderer is a template over the backend, so no call per ray is virtual.

#include "geometry/ray.h"
#include "trace/surface.h"

#include <concepts>
#include <cstdint>
#include <span>

namespace specula {

template <typename B>
concept TraceBackend = requires(const B& backend, const Ray& ray, Hit& hit, std::span<const Ray> rays,
                                std::span<Hit> hits) {
  /// Closest hit along the ray within (tnear, tfar); a miss leaves hit.surface == kNoSurface.
  { backend.intersect(ray, hit) } -> std::same_as<void>;
  /// Whether anything lies within (tnear, tfar).
  { backend.occluded(ray) } -> std::same_as<bool>;
  /// Closest hits of a batch of coherent rays (primary rays of a tile, in packet order).
  { backend.intersect_coherent(rays, hits) } -> std::same_as<void>;
  /// Rays per coherent packet (1 = single rays); the renderer orders primary rays to match.
  { backend.packet_width() } -> std::convertible_to<std::uint32_t>;
  /// The table Hit::surface indexes.
  { backend.surfaces() } -> std::convertible_to<std::span<const Surface>>;
};

} // namespace specula
