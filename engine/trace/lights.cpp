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
  const double dist = std::sqrt(double(d.x) * d.x + double(d.y) * d.y + double(d.z) * d.z);
  if (!(dist > 0.0)) return s; // the point is on the light: no defined direction
  s.distance = float(dist);
  s.to_light = vec3(glm::dvec3(d) / dist);
  double attenuation = 1.0;
  if (light.range > 0.0f) {
    // glTF's recommended window: smooth cut-off at the range.
    const double r = dist / light.range;
    const double w = glm::clamp(1.0 - r * r * r * r, 0.0, 1.0);
    attenuation *= w * w;
  }
  if (light.type == gpu::kLightSpot) {
    const float cos_angle = glm::dot(-s.to_light, light.direction);
    const float span = std::max(light.cos_inner - light.cos_outer, 1e-6f);
    const float t = glm::clamp((cos_angle - light.cos_outer) / span, 0.0f, 1.0f);
    attenuation *= t * t;
  }
  const glm::dvec3 e = glm::dvec3(light.intensity) * attenuation / dist / dist;
  s.irradiance = vec3(glm::min(e, glm::dvec3(kMaxIrradiance)));
  return s;
}

} // namespace specula
