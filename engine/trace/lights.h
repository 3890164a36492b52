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

/// The light's contribution at world point p.
[[nodiscard]] LightSample sample_light(const gpu::GpuLight& light, const vec3& p);

} // namespace specula
