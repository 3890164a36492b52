#pragma once
/// \file
/// The shadow caster's area-light samples (internal to the renderer): a tile's lit pixels as
/// arrays, and one sample of each — its sample point (the pixel's Owen-scrambled Sobol stream),
/// the light point, the shadow ray towards it and what that ray carries. Computed eight pixels at a
/// time with AVX2 where the CPU has it, one at a time otherwise; both give the same bits (the same
/// operations in the same order, each correctly rounded, none fused).

#include "specula/core/math.h"
#include "specula/render/emitters.h"
#include "specula/trace/sampler.h"

#include <cstdint>
#include <vector>

namespace specula::detail {

/// A tile's lit pixels (those with a diffuse part), a column per quantity.
struct ShadowSurfaces {
  std::vector<float> ox, oy, oz;    ///< the shadow rays' origin (offset off the surface)
  std::vector<float> gx, gy, gz;    ///< geometric normal
  std::vector<float> sx, sy, sz;    ///< shading normal
  std::vector<float> ar, ag, ab;    ///< diffuse colour over π
  std::vector<std::uint32_t> pixel; ///< image index
  std::vector<std::uint32_t> set_seed, seed0, seed1; ///< its light-point stream's seeds

  [[nodiscard]] std::size_t size() const { return pixel.size(); }
  void clear();
  void push(const vec3& origin, const vec3& geometric_normal, const vec3& shading_normal,
            const vec3& albedo, std::uint32_t image_pixel, const PixelSampler::Stream2& stream);
};

/// One area-light sample of every surface: whether it gives a shadow ray (the light point is in
/// front of the surface and of the light), and that ray's direction, length and carried value.
struct ShadowLightRays {
  std::vector<std::uint8_t> valid;
  std::vector<float> dx, dy, dz, tfar;
  std::vector<float> vr, vg, vb;
  void resize(std::size_t n);
};

/// Sample `index` of every surface's light-point stream, as rays towards the area lights of
/// `table` (non-empty), each value weighted by inv_samples. `simd`: use AVX2 where the CPU has it
/// (false: one surface at a time; the tests compare the two).
void shadow_light_rays(const EmitterTable& table, const ShadowSurfaces& surfaces,
                       std::uint32_t index, float inv_samples, ShadowLightRays& out,
                       bool simd = true);

/// Whether shadow_light_rays(…, simd = true) runs the AVX2 code on this CPU.
[[nodiscard]] bool shadow_light_rays_vectorised();

} // namespace specula::detail
