#pragma once
#include "specula/core/math.h"

namespace specula {

/// Local translation-rotation-scale, relative to the Parent's world transform (or the world).
struct Transform {
  vec3 translation{0.0f};
  quat rotation{1.0f, 0.0f, 0.0f, 0.0f}; // w, x, y, z
  vec3 scale{1.0f};

  [[nodiscard]] mat4 parent_from_local() const { return compose_trs(translation, rotation, scale); }
  friend bool operator==(const Transform&, const Transform&) = default;
};

} // namespace specula
