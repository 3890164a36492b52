#include "specula/core/math.h"

#include <glm/gtc/matrix_transform.hpp>

namespace specula {

Aabb Aabb::transformed(const mat4& m) const {
  Aabb out;
  if (empty()) return out;
  for (int i = 0; i < 8; ++i) {
    const vec3 corner((i & 1) ? max.x : min.x, (i & 2) ? max.y : min.y, (i & 4) ? max.z : min.z);
    out.grow(vec3(m * vec4(corner, 1.0f)));
  }
  return out;
}

DAabb DAabb::transformed(const Aabb& box, const dmat4& m) {
  DAabb out;
  if (box.empty()) return out;
  for (int i = 0; i < 8; ++i) {
    const dvec3 corner((i & 1) ? box.max.x : box.min.x, (i & 2) ? box.max.y : box.min.y,
                       (i & 4) ? box.max.z : box.min.z);
    out.grow(dvec3(m * dvec4(corner, 1.0)));
  }
  return out;
}

bool is_finite(const mat4& m) {
  for (int c = 0; c < 4; ++c)
    if (!is_finite(m[c])) return false;
  return true;
}

bool is_finite(const dmat4& m) {
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r)
      if (!std::isfinite(m[c][r])) return false;
  return true;
}

mat4 compose_trs(const vec3& translation, const quat& rotation, const vec3& scale) {
  mat4 m = glm::mat4_cast(rotation);
  m[0] *= scale.x;
  m[1] *= scale.y;
  m[2] *= scale.z;
  m[3] = vec4(translation, 1.0f);
  return m;
}

dmat4 compose_trs(const dvec3& translation, const quat& rotation, const vec3& scale) {
  dmat4 m(glm::mat4_cast(rotation)); // the rotation's entries are exact in double
  m[0] *= double(scale.x);
  m[1] *= double(scale.y);
  m[2] *= double(scale.z);
  m[3] = dvec4(translation, 1.0);
  return m;
}

quat rotation_looking_along(const vec3& direction, const vec3& up) {
  const vec3 forward = glm::normalize(direction);
  vec3 reference = up;
  if (std::abs(glm::dot(forward, glm::normalize(up))) > 0.999f) reference = vec3(0, 0, 1);
  const vec3 right = glm::normalize(glm::cross(forward, reference));
  const vec3 true_up = glm::cross(right, forward);
  // Columns of the rotation: +X = right, +Y = up, +Z = -forward.
  mat3 basis(right, true_up, -forward);
  return glm::normalize(glm::quat_cast(basis));
}

} // namespace specula
