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

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
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

/// How far inside its triangle a spawn point is pulled, in units of the length of its error bound
/// (inset_barycentrics). At a concave edge (two faces meeting at an interior angle θ < 180°, as a
/// wall meets the floor), a hit rounded onto the edge can land just behind the neighbouring face,
/// and the offset along its own normal does not bring it back: its shadow ray starts behind the
/// wall. Pulled inward by k·|e|, it is in front of the neighbour by about (k − 1)·|e|·sin θ minus
/// what the normal offset takes back when θ < 90°. With k = 4 every origin of
/// tests/trace/test_ray_offset.cpp's seeded wedges (θ from 20° to 178°, sizes 1e-3 to 1e4) lies
/// in front of both faces; k = 1 already fails below 60°. docs/design/ray-offsets.md.
inline constexpr float kEdgeInset = 4.0f;

/// Barycentrics (b0, b1, b2) for a hit with intersector barycentrics (u, v) on triangle p0 p1 p2,
/// clamped into the triangle (rounding may put them just outside) and then raised, where needed,
/// so that the point lies at least `margin` from every edge: bᵢ ≥ margin / hᵢ, with hᵢ the altitude
/// onto the edge opposite pᵢ; what is added is taken from the other barycentrics in proportion
/// to their room above their own minimum. A triangle too small for the margin gives its centroid;
/// a degenerate one the clamped barycentrics.
[[nodiscard]] inline vec3 inset_barycentrics(const vec3& p0, const vec3& p1, const vec3& p2,
                                             float u, float v, float margin) {
  u = std::clamp(u, 0.0f, 1.0f);
  v = std::clamp(v, 0.0f, 1.0f);
  if (u + v > 1.0f) {
    const float sum = u + v;
    u /= sum;
    v /= sum;
  }
  vec3 b(std::max(0.0f, 1.0f - u - v), u, v);
  // Most hits are far from every edge: bᵢ · 2A ≥ margin · |edge opposite pᵢ|, squared (no root),
  // in float while |cross|² is comfortably normal; the rest is decided in double below.
  const vec3 e0 = p2 - p1, e1 = p0 - p2, e2 = p1 - p0;
  const vec3 c = glm::cross(e2, p2 - p0);
  const float c2 = glm::dot(c, c);
  const float m2 = margin * margin;
  if (c2 > 1e-30f && c2 < 1e30f && b.x * b.x * c2 >= m2 * glm::dot(e0, e0) &&
      b.y * b.y * c2 >= m2 * glm::dot(e1, e1) && b.z * b.z * c2 >= m2 * glm::dot(e2, e2))
    return b;
  // In double: the altitudes of a thin triangle far from the origin lose digits in float.
  const glm::dvec3 q0(p0), q1(p1), q2(p2);
  const double twice_area = glm::length(glm::cross(q1 - q0, q2 - q0));
  if (!(twice_area > 0.0) || !(margin > 0.0f)) return b;
  // margin / hᵢ = margin · |edge opposite pᵢ| / (2 · area).
  const glm::dvec3 lower =
      double(margin) / twice_area *
      glm::dvec3(glm::length(q2 - q1), glm::length(q0 - q2), glm::length(q1 - q0));
  const double floor_sum = lower.x + lower.y + lower.z;
  if (!(floor_sum < 1.0)) return vec3(1.0f / 3.0f);
  double deficit = 0.0, room = 0.0;
  for (int i = 0; i < 3; ++i) {
    if (double(b[i]) < lower[i])
      deficit += lower[i] - double(b[i]);
    else
      room += double(b[i]) - lower[i];
  }
  if (deficit == 0.0) return b;
  // room − deficit = 1 − floor_sum > 0: the others can give what is missing.
  const double keep = 1.0 - deficit / room;
  glm::dvec3 out;
  for (int i = 0; i < 3; ++i)
    out[i] = double(b[i]) < lower[i] ? lower[i] : lower[i] + (double(b[i]) - lower[i]) * keep;
  return vec3(out);
}

/// Where secondary rays leave a hit on a world-space triangle, before the normal offset: the point
/// at the inset barycentrics, and the bound on its rounding error.
struct SpawnPoint {
  vec3 point;
  vec3 error;
};

/// The spawn point of a hit with intersector barycentrics (u, v) on the world-space triangle
/// p0 p1 p2: pulled inside the triangle by `inset` × the length of the hit's error bound
/// (inset_barycentrics), its own error bounded as the hit's. The bound includes the (γ₃ + 1, γ₃)
/// terms of transformed_error with the identity, as for every baked instance.
[[nodiscard]] inline SpawnPoint spawn_point(const vec3& p0, const vec3& p1, const vec3& p2, float u,
                                            float v, float inset = kEdgeInset) {
  const auto error_at = [&](const vec3& b, const vec3& q) {
    return (gamma_bound(3) + 1.0f) * barycentric_error(p0, p1, p2, b.x, b.y, b.z) +
           gamma_bound(3) * glm::abs(q);
  };
  const float w = 1.0f - u - v;
  const vec3 hit = w * p0 + u * p1 + v * p2;
  const vec3 hit_error = error_at(vec3(w, u, v), hit);
  const vec3 b = inset_barycentrics(p0, p1, p2, u, v, inset * glm::length(hit_error));
  if (b == vec3(w, u, v)) return {hit, hit_error}; // far enough from every edge already
  const vec3 q = b.x * p0 + b.y * p1 + b.z * p2;
  return {q, error_at(b, q)};
}

/// std::nextafter(x, +inf) without the library call (it was a call per coordinate of every
/// spawned ray): the next float up; +inf and NaN stay, both zeros give the smallest denormal.
[[nodiscard]] constexpr float next_float_up(float x) {
  if (x != x || x == std::numeric_limits<float>::infinity()) return x;
  if (x == 0.0f) return std::numeric_limits<float>::denorm_min();
  const auto bits = std::bit_cast<std::uint32_t>(x);
  return std::bit_cast<float>(x > 0.0f ? bits + 1u : bits - 1u);
}

/// std::nextafter(x, −inf) likewise.
[[nodiscard]] constexpr float next_float_down(float x) { return -next_float_up(-x); }

/// p moved off the surface along the unit geometric normal n, by enough to clear p_error, and
/// rounded away from the surface. n must point to the side the new ray leaves towards (pass −n to
/// leave through the back, e.g. for refraction).
[[nodiscard]] inline vec3 offset_ray_origin(const vec3& p, const vec3& p_error, const vec3& n) {
  const float d = glm::dot(glm::abs(n), p_error);
  const vec3 offset = d * n;
  vec3 po = p + offset;
  // Round away by the normal's sign, so the origin leaves even an exact (zero-error) plane.
  for (int i = 0; i < 3; ++i) {
    if (n[i] > 0.0f) po[i] = next_float_up(po[i]);
    else if (n[i] < 0.0f) po[i] = next_float_down(po[i]);
  }
  return po;
}

} // namespace specula
