#pragma once
// Shared by the editor tests: the test's own camera projection, written out here rather than
// taken from the editor (so a wrong projection in the editor cannot agree with itself).

#include "specula/scene/components/camera.h"

#include <cmath>
#include <cstdint>

namespace specula::editor::test {

/// A world point → continuous pixel coordinates in a w×h frame: the pinhole of CameraRays (pixel
/// x's centre at x + 0.5).
inline dvec2 pixel_of(const Camera& c, std::uint32_t w, std::uint32_t h, const dvec3& p) {
  const dvec3 f = glm::normalize(c.look_at - c.position);
  const dvec3 r = glm::normalize(glm::cross(f, dvec3(c.up)));
  const dvec3 u = glm::cross(r, f);
  const double t = std::tan(0.5 * double(c.vertical_fov));
  const dvec3 v = p - c.position;
  const double z = glm::dot(v, f);
  return dvec2((glm::dot(v, r) / (z * t * double(w) / double(h)) + 1.0) * 0.5 * double(w),
               (1.0 - glm::dot(v, u) / (z * t)) * 0.5 * double(h));
}

} // namespace specula::editor::test
