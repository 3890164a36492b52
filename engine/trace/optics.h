#pragma once
/// \file
/// Mirror reflection, Snell refraction and the exact unpolarised Fresnel reflectance of a
/// dielectric interface (Whitted, "An Improved Illumination Model for Shaded Display", 1980;
/// pbrt-v4 §9.3 for the Fresnel form).

#include "specula/core/math.h"

#include <cmath>
#include <optional>

namespace specula {

/// d reflected about the unit normal n (either orientation).
[[nodiscard]] inline vec3 reflect_direction(const vec3& d, const vec3& n) {
  return d - 2.0f * glm::dot(d, n) * n;
}

/// Unit direction d refracted through a surface with unit normal n facing the incoming side
/// (dot(d, n) < 0), eta = n_incident / n_transmitted. Empty on total internal reflection.
[[nodiscard]] inline std::optional<vec3> refract_direction(const vec3& d, const vec3& n,
                                                           float eta) {
  const float cos_i = -glm::dot(d, n);
  const float sin2_t = eta * eta * std::max(0.0f, 1.0f - cos_i * cos_i);
  if (sin2_t >= 1.0f) return std::nullopt;
  const float cos_t = std::sqrt(1.0f - sin2_t);
  return glm::normalize(eta * d + (eta * cos_i - cos_t) * n);
}

/// Fraction of light reflected at a dielectric interface for an incident cosine cos_i ∈ [0, 1]
/// and eta = n_incident / n_transmitted: 1 on total internal reflection.
[[nodiscard]] inline float fresnel_dielectric(float cos_i, float eta) {
  cos_i = glm::clamp(cos_i, 0.0f, 1.0f);
  const float sin2_t = eta * eta * (1.0f - cos_i * cos_i);
  if (sin2_t >= 1.0f) return 1.0f;
  const float cos_t = std::sqrt(1.0f - sin2_t);
  // r_parallel and r_perpendicular with n_i = eta·n_t (the common factor n_t cancels).
  const float r_par = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
  const float r_perp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
  return 0.5f * (r_par * r_par + r_perp * r_perp);
}

} // namespace specula
