#pragma once
#include "specula/core/math.h"

namespace specula {

/// The largest colour × intensity (per component) the loaders accept. With it, and the tracers'
/// falloff evaluated without overflow (trace/lights.cpp), every pixel stays finite; real scenes are
/// far below it (the sun as a point light at 1 AU in metres is about 3e27 cd, but in lux 1.2e5).
inline constexpr float kMaxLightIntensity = 1e20f;

/// A punctual light (the KHR_lights_punctual model). Position and direction come from the entity's
/// WorldTransform: the light sits at its origin and points along its -Z axis.
/// Point and spot intensity is in candela (W/sr-like), directional in lux.
struct Light {
  enum class Type { Point, Directional, Spot };
  Type type = Type::Point;
  vec3 color{1.0f};
  float intensity = 1.0f;
  float range = 0.0f;                      ///< 0: unlimited
  float inner_cone = 0.0f;                 ///< spot, radians
  float outer_cone = glm::radians(45.0f);  ///< spot, radians
  friend bool operator==(const Light&, const Light&) = default;
};

} // namespace specula
