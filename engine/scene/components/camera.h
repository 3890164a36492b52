#pragma once
#include "specula/core/math.h"

#include <vector>

namespace specula {

/// A pinhole camera in world space (positions in double, like Transform::translation).
struct Camera {
  dvec3 position{0.0, 0.0, 5.0};
  dvec3 look_at{0.0};
  vec3 up{0.0f, 1.0f, 0.0f};
  float vertical_fov = glm::radians(45.0f); ///< radians
  /// Width / height as the scene file gives it (JSON "aspect", default the settings' width /
  /// height; glTF aspectRatio), kept so that the scene writes back unchanged. Informational only:
  /// renders use the image's own width / height (CameraRays), so pixels stay square at any size.
  float aspect = 1.0f;
  friend bool operator==(const Camera&, const Camera&) = default;
};

/// An optional camera path for benchmarks: animation_system moves the entity's Camera along it
/// (linear position and look-at, the up vector turned between keys: the camera's roll), looping.
struct CameraPath {
  struct Key {
    float time = 0.0f;
    dvec3 position{0.0};
    dvec3 look_at{0.0};
    vec3 up{0.0f, 1.0f, 0.0f}; ///< any length but 0; never along the view direction
    friend bool operator==(const Key&, const Key&) = default;
  };
  std::vector<Key> keys;
  float time = 0.0f;
  bool loop = true;
  friend bool operator==(const CameraPath&, const CameraPath&) = default;
};

} // namespace specula
