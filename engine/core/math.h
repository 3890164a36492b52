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

using glm::dmat3;
using glm::dmat4;
using glm::dvec3;
using glm::dvec4;
using glm::mat3;
using glm::mat4;
using glm::quat;
using glm::uvec3;
using glm::vec2;
using glm::vec3;
using glm::vec4;

/// The representable range (docs/design/large-worlds.md): the largest magnitude of any coordinate
/// Specula accepts — object-space vertices and primitive sizes (float), local translations,
/// camera and light positions, animation keys and composed world positions and bounds (double).
/// At 1e12 a double still resolves 1.2e-4, finer than float resolves around the camera in render
/// space (SceneLayer), so the whole range renders like the origin; and camera-relative render
/// coordinates (at most 2e12) stay far inside what Embree accepts (|x| <= 1.8e18) and what the
/// watertight intersection's products can hold in float (~(2e12)^3 < 3.4e38).
inline constexpr double kMaxCoordinate = 1e12;
/// How messages state that range.
inline constexpr const char* kCoordinateRangeText = "the representable range [-1e12, 1e12]";

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

/// An axis-aligned box in double precision: world-space bounds, whose coordinates may be far
/// from the origin (Aabb holds object- and render-space boxes).
struct DAabb {
  dvec3 min{std::numeric_limits<double>::infinity()};
  dvec3 max{-std::numeric_limits<double>::infinity()};

  [[nodiscard]] bool empty() const { return min.x > max.x || min.y > max.y || min.z > max.z; }
  void grow(const dvec3& p) {
    min = glm::min(min, p);
    max = glm::max(max, p);
  }
  void grow(const DAabb& b) {
    min = glm::min(min, b.min);
    max = glm::max(max, b.max);
  }
  [[nodiscard]] dvec3 center() const { return 0.5 * (min + max); }
  [[nodiscard]] dvec3 extent() const { return max - min; }
  /// The box of `box`'s eight corners transformed by m, in double.
  [[nodiscard]] static DAabb transformed(const Aabb& box, const dmat4& m);
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
[[nodiscard]] inline bool is_finite(const dvec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}
[[nodiscard]] bool is_finite(const mat4& m);
[[nodiscard]] bool is_finite(const dmat4& m);

/// True when every component is finite and within ±kMaxCoordinate.
[[nodiscard]] inline bool in_range(double v) { return std::abs(v) <= kMaxCoordinate; }
[[nodiscard]] inline bool in_range(const dvec3& v) {
  return in_range(v.x) && in_range(v.y) && in_range(v.z);
}
[[nodiscard]] inline bool in_range(const vec3& v) { return in_range(dvec3(v)); }

/// Composes translation * rotation * scale (the glTF order).
[[nodiscard]] mat4 compose_trs(const vec3& translation, const quat& rotation, const vec3& scale);
/// The same in double: how Transform composes, so that a translation far from the origin keeps
/// every bit it was given.
[[nodiscard]] dmat4 compose_trs(const dvec3& translation, const quat& rotation, const vec3& scale);

/// Rotation that turns the -Z axis towards `direction` with `up` kept as close to +Y as possible
/// (the camera/light convention of glTF). `direction` must be non-zero.
[[nodiscard]] quat rotation_looking_along(const vec3& direction, const vec3& up = vec3(0, 1, 0));

} // namespace specula
