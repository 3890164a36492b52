#pragma once
/// \file
/// Sampling the scene's area lights (render/emitters.h) from a shading point: a triangle picked
/// power-proportionally, a point uniform on it, the density converted to solid angle at the
/// shading point (pdf_A · d² / |cos θ_light|); and the same density for a point a BSDF-sampled ray
/// happened to hit, for multiple importance sampling.

#include "specula/render/emitters.h"

#include <cmath>
#include <limits>

namespace specula {

struct AreaLightSample {
  vec3 position{0.0f};   ///< on the light, render space
  vec3 normal{0.0f};     ///< the triangle's unit normal (emission is two-sided)
  vec3 emission{0.0f};   ///< radiance leaving the light towards the point
  vec3 to_light{0.0f};   ///< unit, from the shading point
  float distance = 0.0f; ///< from the shading point
  float pdf = 0.0f;      ///< solid angle at the shading point; 0: no usable sample
  std::uint32_t triangle = EmitterTable::kNone;
};

/// Solid-angle density of sampling light point `q` with normal `n` on triangle `e` from `p`.
[[nodiscard]] inline float area_light_pdf(const EmitterTriangle& e, const vec3& p, const vec3& q) {
  if (!(e.area > 0.0f)) return 0.0f; // a degenerate triangle (never picked): not 0 / 0
  const vec3 d = q - p;
  const float dist2 = glm::dot(d, d);
  if (!(dist2 > 0.0f)) return 0.0f;
  const float cos_l = std::abs(glm::dot(e.normal, d)) / std::sqrt(dist2);
  if (!(cos_l > 0.0f)) return 0.0f;
  return e.pick / e.area * dist2 / cos_l;
}

/// A light point on emitter triangle `k` for shading point p: (u1, u2) place it uniformly by area
/// (the square-root map); the density includes the triangle's picking probability.
[[nodiscard]] inline AreaLightSample sample_emitter_triangle(const EmitterTable& table,
                                                             std::uint32_t k, const vec3& p,
                                                             float u1, float u2) {
  AreaLightSample s;
  const EmitterTriangle& e = table.triangles()[k];
  const float r = std::sqrt(u1);
  const float b1 = 1.0f - r, b2 = u2 * r;
  s.position = e.p0 + b1 * e.e1 + b2 * e.e2;
  s.normal = e.normal;
  s.emission = e.emission;
  s.triangle = k;
  const vec3 d = s.position - p;
  const float dist = glm::length(d);
  if (!(dist > 0.0f) || !std::isfinite(dist)) return s;
  s.distance = dist;
  s.to_light = d / dist;
  const float cos_l = std::abs(glm::dot(e.normal, s.to_light));
  if (!(cos_l > 0.0f)) return s;
  s.pdf = e.pick / e.area * dist * dist / cos_l;
  if (!std::isfinite(s.pdf)) s.pdf = 0.0f;
  return s;
}

/// A light point for shading point p from three uniform numbers: u_pick picks the triangle,
/// (u1, u2) the point on it (uniform by area: the square-root map).
[[nodiscard]] inline AreaLightSample sample_area_light(const EmitterTable& table, const vec3& p,
                                                       float u_pick, float u1, float u2) {
  if (table.empty()) return AreaLightSample{};
  return sample_emitter_triangle(table, table.pick(u_pick), p, u1, u2);
}

/// The power heuristic (β = 2) weight of a strategy with density `a` against one with `b`:
/// a² / (a² + b²), computed as 1 / (1 + (b/a)²) so that w(a, b) + w(b, a) = 1 for every pair,
/// also where a² or b² would overflow to inf or underflow to 0 (a² / (a² + b²) gave 1 + 1 for two
/// huge densities and 0 + 0 for two tiny ones). Equal densities (both 0 or both inf included)
/// share ½ each; NaN or negative densities count as 0.
[[nodiscard]] inline float power_heuristic(float a, float b) {
  a = a > 0.0f ? a : 0.0f;
  b = b > 0.0f ? b : 0.0f;
  if (a == b) return 0.5f;
  if (a == 0.0f || std::isinf(b)) return 0.0f;
  if (b == 0.0f || std::isinf(a)) return 1.0f;
  const float r = b / a;
  return 1.0f / (1.0f + r * r);
}

} // namespace specula
