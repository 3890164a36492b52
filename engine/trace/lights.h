#pragma once
/// \file
/// Lights in world space, gathered once per frame, and their contribution at a point
/// (KHR_lights_punctual conventions: point/spot intensity in candela, directional in lux,
/// spot cone smoothstep-free quadratic falloff, optional range window).

#include "specula/core/math.h"
#include "specula/ecs/registry.h"
#include "specula/scene/components/light.h"

#include <limits>
#include <vector>

namespace specula {

struct SceneLight {
  Light::Type type = Light::Type::Point;
  vec3 position{0.0f};
  vec3 direction{0.0f, 0.0f, -1.0f}; ///< where the light points (directional, spot)
  vec3 intensity{1.0f};              ///< colour × intensity
  float range = 0.0f;
  float cos_inner = 1.0f;
  float cos_outer = 0.0f;
};

/// Every entity with Light and WorldTransform.
[[nodiscard]] std::vector<SceneLight> gather_lights(ecs::Registry& registry);

struct LightSample {
  vec3 to_light{0.0f}; ///< unit direction from the point to the light
  float distance = std::numeric_limits<float>::infinity();
  vec3 irradiance{0.0f}; ///< at normal incidence (multiply by the cosine)
};

/// The light's contribution at world point p.
[[nodiscard]] LightSample sample_light(const SceneLight& light, const vec3& p);

} // namespace specula
