#pragma once
/// \file
/// Shading points of many hits at once (internal to the renderer): shading_point (shading.h, with
/// its error bounds) for every hit of a wave, eight at a time with AVX2 where the CPU has it. The
/// vector code repeats the scalar code's operations in their order, each correctly rounded and
/// none fused, so the two give the same bits. It takes the common case: a hit on a baked
/// (kInstanceIdentity) instance whose barycentrics lie in the triangle and whose spawn point needs
/// no inset (inset_barycentrics' fast test). Every other hit is computed one at a time.

#include "specula/geometry/ray.h"
#include "specula/trace/shading.h"

#include <cstddef>
#include <span>

namespace specula::detail {

/// Directions of a wave's rays: direction i is (x[i · stride], y[i · stride], z[i · stride]), so
/// that they can be a field of an array of structures (aos) or three arrays (PrimaryHits).
struct Directions {
  const float* x = nullptr;
  const float* y = nullptr;
  const float* z = nullptr;
  std::size_t stride = 1;
  /// Direction fields `stride` words apart, the first at `first` (x, y, z consecutive).
  [[nodiscard]] static Directions aos(const float* first, std::size_t stride) {
    return {first, first + 1, first + 2, stride};
  }
  [[nodiscard]] vec3 operator[](std::size_t i) const {
    return vec3(x[i * stride], y[i * stride], z[i * stride]);
  }
};

/// out[i] = shading_point(tables, hits[i], directions[i], true) for every hit i that hit
/// something (a miss's entry is left as it was). `simd` false: one hit at a time (the tests
/// compare the two). Returns how many hits the vector code took.
std::size_t shading_points(const SceneTables& tables, std::span<const Hit> hits,
                           const Directions& directions, std::span<ShadingPoint> out,
                           bool simd = true);

/// Whether shading_points(…, simd = true) runs the AVX2 code on this CPU.
[[nodiscard]] bool shading_points_vectorised();

} // namespace specula::detail
