#pragma once
/// \file
/// Math on GLM: the vector types Specula uses everywhere, axis-aligned boxes, TRS helpers and
/// finiteness checks used by every loader.

#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

#include <cmath>
#include <limits>
#include <span>

namespace specula {

using glm::mat3;
using glm::mat4;
using glm::quat;
using glm::uvec3;
using glm::vec2;
using glm::vec3;
using glm::vec4;

/// Axis-aligned bounding box; empty (min > max) by default, so grow() from nothing works.
struct Aabb {
  vec3 min{std::numeric_limits<float>::infinity()};
  vec3 max{-std::numeric_limits<float>::infinity()};

  [[nodiscard]] bool empty() const { return min.x > max.x || min.y > max.y || min.z > max.z; }
  void grow(const vec3& p) {
    min = glm::min(min, p);
    max = glm::max(max, p);
  }
  void grow(const Aabb& b) {
    min = glm::min(min, b.min);
    max = glm::max(max, b.max);
  }
  [[nodiscard]] vec3 center() const { return 0.5f * (min + max); }
  [[nodiscard]] vec3 extent() const { return max - min; }
  /// The box of this box's eight corners transformed by m (conservative for rotations).
  [[nodiscard]] Aabb transformed(const mat4& m) const;
};

[[nodiscard]] inline bool is_finite(float v) { return std::isfinite(v); }
[[nodiscard]] inline bool is_finite(const vec2& v) { return std::isfinite(v.x) && std::isfinite(v.y); }
[[nodiscard]] inline bool is_finite(const vec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
[[nodiscard]] inline bool is_finite(const vec4& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z) && std::isfinite(v.w);
}
[[nodiscard]] inline bool is_finite(const quat& q) {
  return std::isfinite(q.x) && std::isfinite(q.y) && std::isfinite(q.z) && std::isfinite(q.w);
}
[[nodiscard]] bool is_finite(const mat4& m);

/// Composes translation * rotation * scale (the glTF order).
[[nodiscard]] mat4 compose_trs(const vec3& translation, const quat& rotation, const vec3& scale);

/// Rotation that turns the -Z axis towards `direction` with `up` kept as close to +Y as possible
/// (the camera/light convention of glTF). `direction` must be non-zero.
[[nodiscard]] quat rotation_looking_along(const vec3& direction, const vec3& up = vec3(0, 1, 0));

} // namespace specula
