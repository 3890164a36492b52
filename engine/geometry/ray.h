#pragma once
/// \file
/// Rays and hits shared by every backend.

#include "specula/core/math.h"

#include <cmath>
#include <cstdint>
#include <limits>

namespace specula {

struct Ray {
  vec3 origin{0.0f};
  float tnear = 0.0f;
  vec3 direction{0.0f, 0.0f, -1.0f};
  float tfar = std::numeric_limits<float>::infinity();
};

/// Whether a ray can be traced: finite origin and direction, a non-zero direction, and a
/// non-empty interval 0 ≤ tnear ≤ tfar with tnear finite (tfar may be +inf). Every backend answers
/// any other ray with a miss (and "not occluded") without tracing it.
[[nodiscard]] inline bool traceable(const vec3& origin, const vec3& direction, float tnear,
                                    float tfar) {
  return is_finite(origin) && is_finite(direction) &&
         !(direction.x == 0.0f && direction.y == 0.0f && direction.z == 0.0f) &&
         !std::isnan(tfar) && tnear >= 0.0f && tnear <= tfar &&
         tnear < std::numeric_limits<float>::infinity();
}
[[nodiscard]] inline bool traceable(const Ray& r) {
  return traceable(r.origin, r.direction, r.tnear, r.tfar);
}

/// Hit::instance of a miss.
inline constexpr std::uint32_t kNoInstance = 0xFFFFFFFFu;

/// A ray's closest hit. `instance` is the scene layer's instance slot (SceneTables::instances;
/// kNoInstance: a miss) and `primitive` the triangle within its mesh; `object_normal` is the
/// geometric normal in the space of the instance's mesh (world space for the baked static set),
/// not normalised, facing whichever way the triangle's winding says — resolving a hit stays cheap,
/// only shaded hits pay for the transform; `uv` are the barycentrics of vertices 1 and 2.
struct Hit {
  float t = std::numeric_limits<float>::infinity();
  std::uint32_t instance = kNoInstance;
  std::uint32_t primitive = 0;
  vec2 uv{0.0f};
  vec3 object_normal{0.0f};
  [[nodiscard]] bool hit() const { return instance != kNoInstance; }
};

} // namespace specula
