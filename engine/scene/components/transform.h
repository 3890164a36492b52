#pragma once
#include "specula/core/math.h"

namespace specula {

/// Local translation-rotation-scale, relative to the Parent's world transform (or the world).
/// The translation is in double, so that a position far from the origin (1e7, 1e9) keeps the
/// precision it was given; rotation and scale stay float (docs/design/large-worlds.md).
struct Transform {
  dvec3 translation{0.0};
  quat rotation{1.0f, 0.0f, 0.0f, 0.0f}; // w, x, y, z
  vec3 scale{1.0f};

  [[nodiscard]] dmat4 parent_from_local() const {
    return compose_trs(translation, rotation, scale);
  }
  friend bool operator==(const Transform&, const Transform&) = default;
};

/// While present, the entity and its subtree are left out of the frame: the transform system
/// collapses their world transforms to their origins (a zero linear part), which the scene layer
/// and every tracer treat as hidden (`accel.hidden_instances`). animation_system sets it from an
/// Animation's visibility keys; it is state, not part of the scene file.
struct Hidden {
  friend bool operator==(const Hidden&, const Hidden&) = default;
};

} // namespace specula
