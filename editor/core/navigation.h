#pragma once
/// \file
/// Camera navigation as pure functions of input deltas (the window's mouse and keys, or tests).

#include "specula/scene/components/camera.h"

namespace specula::editor {

/// Turns the camera about its look-at point: dx, dy in pixels, `radians_per_pixel` each. The
/// distance to the look-at point is kept; the pitch stops short of the poles (never flips).
[[nodiscard]] Camera orbit(const Camera& camera, double dx, double dy,
                           double radians_per_pixel = 0.005);

/// Moves the camera and its look-at point together: `move` is (right, up, forward) in units
/// of `speed` per second over dt seconds; dx, dy (pixels) turn the view about the camera
/// (yaw about world up, pitch about its right axis), `radians_per_pixel` each.
[[nodiscard]] Camera fly(const Camera& camera, const dvec3& move, double dt, double speed,
                         double dx = 0.0, double dy = 0.0, double radians_per_pixel = 0.003);

} // namespace specula::editor
