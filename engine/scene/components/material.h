#pragma once
#include "specula/core/math.h"

namespace specula {

/// The largest emission component (and background colour) the loaders accept: a pixel sums at most
/// a few thousand such values weighted ≤ 1, far from float's 3.4e38.
inline constexpr float kMaxEmission = 1e20f;

/// Surface description shared by every backend. Reflectivity and transmission are weights in
/// [0, 1] (their sum ≤ 1); the rest of the weight is diffuse with base_color.
struct Material {
  vec3 base_color{0.8f};
  vec3 emission{0.0f};
  float reflectivity = 0.0f; ///< mirror reflection weight
  float transmission = 0.0f; ///< refraction weight
  float ior = 1.5f;          ///< index of refraction for transmission (≥ 1)
  float roughness = 0.0f;    ///< reserved: stored and round-tripped, not yet used by tracers

  [[nodiscard]] bool is_reflective() const { return reflectivity > 0.0f; }
  [[nodiscard]] bool is_refractive() const { return transmission > 0.0f; }
  friend bool operator==(const Material&, const Material&) = default;
};

} // namespace specula
