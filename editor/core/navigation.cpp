#include "editor/core/navigation.h"

#include <algorithm>
#include <cmath>

namespace specula::editor {

namespace {

using dvec2 = glm::dvec2;

/// (yaw, pitch) of a direction about world +Y, and back.
dvec2 angles(const dvec3& d) {
  return dvec2(std::atan2(d.x, d.z), std::asin(std::clamp(d.y, -1.0, 1.0)));
}
dvec3 direction(const dvec2& a) {
  return dvec3(std::cos(a.y) * std::sin(a.x), std::sin(a.y), std::cos(a.y) * std::cos(a.x));
}
constexpr double kMaxPitch = 1.55; // just under π/2: the view never turns over the pole

} // namespace

Camera orbit(const Camera& camera, double dx, double dy, double radians_per_pixel) {
  const dvec3 offset = camera.position - camera.look_at;
  const double distance = glm::length(offset);
  if (!(distance > 0.0)) return camera;
  dvec2 a = angles(offset / distance);
  a.x -= dx * radians_per_pixel;
  a.y = std::clamp(a.y + dy * radians_per_pixel, -kMaxPitch, kMaxPitch);
  Camera out = camera;
  out.position = camera.look_at + direction(a) * distance;
  return out;
}

Camera fly(const Camera& camera, const dvec3& move, double dt, double speed, double dx, double dy,
           double radians_per_pixel) {
  const dvec3 view = camera.look_at - camera.position;
  const double distance = glm::length(view);
  if (!(distance > 0.0)) return camera;
  dvec2 a = angles(view / distance);
  a.x -= dx * radians_per_pixel;
  a.y = std::clamp(a.y - dy * radians_per_pixel, -kMaxPitch, kMaxPitch);
  const dvec3 forward = direction(a);
  const dvec3 right = glm::normalize(glm::cross(forward, dvec3(0.0, 1.0, 0.0)));
  const dvec3 up = glm::cross(right, forward);
  const dvec3 step = (move.x * right + move.y * up + move.z * forward) * (speed * dt);
  Camera out = camera;
  out.position = camera.position + step;
  out.look_at = out.position + forward * distance;
  return out;
}

} // namespace specula::editor
