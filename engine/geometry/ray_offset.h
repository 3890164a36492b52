#pragma once
/// \file
/// Self-intersection-free ray origins by error bounds (the method of pbrt, Pharr, Jakob, Humphreys,
/// §6.8.4 of the 4th edition, equivalent in intent to Wächter & Binder, Ray Tracing Gems ch. 6):
/// a hit point computed from barycentrics carries a rounding error bounded per coordinate (see
/// barycentric_error; plus the transform's rounding when placed in world space). Moving the point along
/// the geometric normal by that bound's projection, then rounding outward, puts the new origin
/// strictly on the leaving side. The offset scales with the triangle's own magnitude — there is
/// no global epsilon, and none of the fixed near-origin offset that makes the integer-ULP method
/// too coarse on millimetre scenes.

#include "specula/core/math.h"

#include <cmath>
#include <limits>

namespace specula {

/// γₙ = n·u / (1 − n·u), u = 2⁻²⁴: the bound on n successive float roundings (Higham).
[[nodiscard]] constexpr float gamma_bound(int n) {
  constexpr float u = std::numeric_limits<float>::epsilon() * 0.5f;
  return (float(n) * u) / (1.0f - float(n) * u);
}

/// Error bound of a hit point p = b0·p0 + b1·p1 + b2·p2 computed in float, barycentrics b from
/// the intersector. Two parts: the interpolation's own rounding, γ₇·Σ|bᵢ·pᵢ| per coordinate, and
/// the intersector's, which rounds in a ray-relative, sheared frame (Woop et al., "Watertight
/// Ray/Triangle Intersection", 2013) where every coordinate of the vertices mixes into each
/// other: γ₈ of the vertices' largest coordinate magnitude, on every axis. Without the second
/// part a point on an axis-aligned plane through 0 has a zero bound, and its one-ULP denormal
/// offset is flushed to zero by FTZ/DAZ: the spawned ray then hits its own plane.
[[nodiscard]] inline vec3 barycentric_error(const vec3& p0, const vec3& p1, const vec3& p2, float b0,
                                            float b1, float b2) {
  const vec3 largest = glm::max(glm::abs(p0), glm::max(glm::abs(p1), glm::abs(p2)));
  const float magnitude = std::max(largest.x, std::max(largest.y, largest.z));
  return gamma_bound(7) * (glm::abs(b0 * p0) + glm::abs(b1 * p1) + glm::abs(b2 * p2)) +
         vec3(gamma_bound(8) * magnitude);
}

/// Error bound after transforming a point p (with error p_error) by the affine m in float.
[[nodiscard]] inline vec3 transformed_error(const mat4& m, const vec3& p, const vec3& p_error) {
  const mat3 abs_m(glm::abs(vec3(m[0])), glm::abs(vec3(m[1])), glm::abs(vec3(m[2])));
  const vec3 abs_t = glm::abs(vec3(m[3]));
  return (gamma_bound(3) + 1.0f) * (abs_m * p_error) + gamma_bound(3) * (abs_m * glm::abs(p) + abs_t);
}

/// p moved off the surface along the unit geometric normal n, by enough to clear p_error, and
/// rounded away from the surface. n must point to the side the new ray leaves towards (pass −n to
/// leave through the back, e.g. for refraction).
[[nodiscard]] inline vec3 offset_ray_origin(const vec3& p, const vec3& p_error, const vec3& n) {
  const float d = glm::dot(glm::abs(n), p_error);
  const vec3 offset = d * n;
  vec3 po = p + offset;
  // Round away by the normal's sign, so the origin leaves even an exact (zero-error) plane.
  for (int i = 0; i < 3; ++i) {
    if (n[i] > 0.0f) po[i] = std::nextafter(po[i], std::numeric_limits<float>::infinity());
    else if (n[i] < 0.0f) po[i] = std::nextafter(po[i], -std::numeric_limits<float>::infinity());
  }
  return po;
}

} // namespace specula
