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

/// out[i] = shading_point(tables, hits[i], direction i, true) for every hit i that hit something
/// (a miss's entry is left as it was). Direction i is (directions[i · stride], … + 1, … + 2), so
/// that it can be a field of an array of structures (a Ray's direction: stride 8).
/// `simd` false: one hit at a time (the tests compare the two). Returns how many hits the vector
/// code took.
std::size_t shading_points(const SceneTables& tables, std::span<const Hit> hits,
                           const float* directions, std::size_t stride, std::span<ShadingPoint> out,
                           bool simd = true);

/// Whether shading_points(…, simd = true) runs the AVX2 code on this CPU.
[[nodiscard]] bool shading_points_vectorised();

} // namespace specula::detail
