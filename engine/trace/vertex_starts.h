#pragma once
/// \file
/// What a path vertex's shading starts from, for a whole wave at once (internal to the
/// renderer): the origin of the rays that leave it on its geometric normal's side
/// (offset_ray_origin), each punctual light's sample (sample_light, with the shadow ray's length
/// from that origin) and its area-light sample (sample_area_light). Eight vertices at a time
/// with AVX2 where the CPU has it, one at a time otherwise; both give the same bits (the same
/// operations in the same order, each correctly rounded, none fused).

#include "specula/geometry/ray.h"
#include "specula/render/emitters.h"
#include "specula/shared/scene_layout.h"
#include "specula/trace/shading.h"

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace specula::detail {

/// Per vertex of a wave, a column per quantity.
struct VertexStarts {
  std::vector<float> ox, oy, oz; ///< offset_ray_origin(spawn point, its error, geometric normal)
  std::vector<float> lx, ly, lz; ///< the area-light sample's unit direction …
  std::vector<float> distance;   ///< … its distance …
  std::vector<float> pdf;        ///< … solid-angle density (0: no usable sample) …
  std::vector<float> er, eg, eb; ///< … and the picked triangle's emission
  /// Per punctual light l and vertex k (entry l · count + k, count the vertices): sample_light's
  /// direction and irradiance at the vertex, and shadow_tfar from its origin.
  std::vector<float> plx, ply, plz, pir, pig, pib, ptfar;

  void resize(std::size_t vertices, std::size_t lights);
  [[nodiscard]] std::size_t count() const { return ox.size(); }
  [[nodiscard]] vec3 origin(std::size_t k) const { return vec3(ox[k], oy[k], oz[k]); }
  [[nodiscard]] vec3 to_light(std::size_t k) const { return vec3(lx[k], ly[k], lz[k]); }
  [[nodiscard]] vec3 emission(std::size_t k) const { return vec3(er[k], eg[k], eb[k]); }
  [[nodiscard]] vec3 light_direction(std::size_t entry) const {
    return vec3(plx[entry], ply[entry], plz[entry]);
  }
  [[nodiscard]] vec3 irradiance(std::size_t entry) const {
    return vec3(pir[entry], pig[entry], pib[entry]);
  }
};

/// The wave's vertices: vertex k is the hit hits[k / per_point] with shading point
/// points[k / per_point] (several paths may share a hit: a pixel's samples at its primary hit).
/// Samples of every light of `lights`; area-light samples where `emitters` is given: vertex k's
/// numbers (pick, then the point) are light_u[k · stride + 0 … 2]. Entries of misses are left
/// undefined.
struct VertexInputs {
  std::span<const Hit> hits;
  std::span<const ShadingPoint> points;
  std::size_t per_point = 1;
  std::size_t count = 0; ///< vertices
  const EmitterTable* emitters = nullptr;
  const float* light_u = nullptr;
  std::size_t stride = 0; ///< in floats
  std::span<const gpu::GpuLight> lights;
};

/// Fills `out` (resized to in.count). `simd` false: one vertex at a time (the tests compare the
/// two).
void vertex_starts(const VertexInputs& in, VertexStarts& out, bool simd = true);

/// Whether vertex_starts(…, simd = true) runs the AVX2 code on this CPU.
[[nodiscard]] bool vertex_starts_vectorised();

} // namespace specula::detail
