#pragma once
/// \file
/// A light's contribution at a point (KHR_lights_punctual conventions: point/spot intensity in
/// candela, directional in lux, spot cone smoothstep-free quadratic falloff, optional range
/// window). Lights come from the scene layer's light table (SceneTables::lights), in world space.

#include "specula/core/math.h"
#include "specula/shared/scene_layout.h"

#include <limits>

namespace specula {

struct LightSample {
  vec3 to_light{0.0f}; ///< unit direction from the point to the light
  float distance = std::numeric_limits<float>::infinity();
  vec3 irradiance{0.0f}; ///< at normal incidence (multiply by the cosine)
};

/// The most irradiance one light gives a point: the inverse-square law is followed exactly down to
/// the distance where it would exceed this (1e-5 from a light of the largest accepted intensity,
/// kMaxLightIntensity = 1e20), and capped closer, so that a pixel's sum stays finite.
inline constexpr float kMaxIrradiance = 1e30f;

/// The light's contribution at world point p. The falloff is I / d / d, with d in double: I / d²
/// in float overflowed d² beyond 1.8e19 and, under the render threads' flush-to-zero, lost 1 / d²
/// beyond about 1e19 (a light of 1e20 cd at 1e19 gave 0 instead of 1e-18).
[[nodiscard]] LightSample sample_light(const gpu::GpuLight& light, const vec3& p);

} // namespace specula
