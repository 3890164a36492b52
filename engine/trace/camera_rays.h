#pragma once
/// \file
/// Primary rays of a pinhole camera.

#include "specula/geometry/ray.h"
#include "specula/scene/components/camera.h"
#include "specula/trace/packet_tile.h"

#include <cmath>
#include <cstdint>

namespace specula {

/// Camera basis and image-plane scale for one frame. The image's own aspect (width / height) is
/// used, so rendering at any size never stretches the picture; vertical_fov is kept. Rays are in
/// render space: world space translated by −render_origin (SceneLayer::render_origin()), the
/// origin and view direction computed in double from the camera's world positions, so a camera
/// far from the world origin loses no precision.
struct CameraRays {
  vec3 origin{0.0f};
  vec3 forward{0.0f, 0.0f, -1.0f};
  vec3 right{1.0f, 0.0f, 0.0f};
  vec3 up{0.0f, 1.0f, 0.0f};
  float inv_width = 1.0f;
  float inv_height = 1.0f;

  CameraRays(const Camera& camera, std::uint32_t width, std::uint32_t height,
             const dvec3& render_origin = dvec3(0.0)) {
    // Differences in double (exact for the nearby points of a far-away camera), rounded once to
    // float; the rest in float, as for a camera at the world origin.
    origin = vec3(camera.position - render_origin);
    forward = glm::normalize(vec3(camera.look_at - camera.position));
    vec3 r = glm::cross(forward, camera.up);
    if (glm::length(r) < 1e-6f)
      r = glm::cross(forward, std::abs(forward.y) < 0.9f ? vec3(0, 1, 0) : vec3(1, 0, 0));
    const float tan_half = std::tan(0.5f * camera.vertical_fov);
    const float aspect = float(width) / float(height);
    right = glm::normalize(r) * tan_half * aspect;
    up = glm::normalize(glm::cross(glm::normalize(r), forward)) * tan_half;
    inv_width = 1.0f / float(width);
    inv_height = 1.0f / float(height);
  }

  /// Unit directions of the rays through every pixel of `tile`, in its trace order, one array per
  /// component (each holds tile.pixel_count() floats): bit-identical to ray(x, y).direction, a
  /// tile at a time — the image-plane offsets once per column and row, the normalisation
  /// vectorised. Every ray starts at `origin`.
  void tile_directions(const PacketTile& tile, float* dx, float* dy, float* dz) const;

  /// The ray through the centre of pixel (x, y), row 0 at the top.
  [[nodiscard]] Ray ray(std::uint32_t x, std::uint32_t y) const {
    const float sx = 2.0f * (float(x) + 0.5f) * inv_width - 1.0f;
    const float sy = 1.0f - 2.0f * (float(y) + 0.5f) * inv_height;
    Ray r;
    r.origin = origin;
    r.direction = glm::normalize(forward + sx * right + sy * up);
    return r;
  }
};

} // namespace specula
