#include "specula/trace/lights.h"

#include <cmath>

namespace specula {

LightSample sample_light(const gpu::GpuLight& light, const vec3& p) {
  LightSample s;
  if (light.type == gpu::kLightDirectional) {
    s.to_light = -light.direction;
    s.irradiance = light.intensity;
    return s;
  }
  const vec3 d = light.position - p;
  const float dist2 = glm::dot(d, d);
  if (!(dist2 > 0.0f)) return s; // the point is on the light: no defined direction
  s.distance = std::sqrt(dist2);
  s.to_light = d / s.distance;
  float attenuation = 1.0f / dist2;
  if (light.range > 0.0f) {
    // glTF's recommended window: smooth cut-off at the range.
    const float r = s.distance / light.range;
    const float w = glm::clamp(1.0f - r * r * r * r, 0.0f, 1.0f);
    attenuation *= w * w;
  }
  if (light.type == gpu::kLightSpot) {
    const float cos_angle = glm::dot(-s.to_light, light.direction);
    const float span = std::max(light.cos_inner - light.cos_outer, 1e-6f);
    const float t = glm::clamp((cos_angle - light.cos_outer) / span, 0.0f, 1.0f);
    attenuation *= t * t;
  }
  s.irradiance = light.intensity * attenuation;
  return s;
}

} // namespace specula
