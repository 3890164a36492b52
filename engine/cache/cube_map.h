#pragma once
/// \file
/// Cube-map addressing of a ray-cache cube (Ruff, Clua, Fernandes 2013, §III-B, eq. 5): the face
/// is chosen by the major axis of the direction s and the texel coordinates are
/// t_u = ½(t'_u/|m| + 1), t_v = ½(t'_v/|m| + 1) with (t'_u, t'_v, m) from the OpenGL cube-map
/// table (OpenGL 4.6 core, table 8.19): faces in the order +X, −X, +Y, −Y, +Z, −Z; nearest-texel
/// sampling. Ties between axes go to x, then y (OpenGL leaves them to the implementation).
/// Header-only and free of the engine's other types, so a GLSL port reads the same arithmetic.

#include "specula/core/math.h"

#include <algorithm>
#include <cmath>
#include <cstdint>

namespace specula::cache {

inline constexpr std::uint32_t kFaceCount = 6;
enum class CubeFace : std::uint32_t { PosX = 0, NegX = 1, PosY = 2, NegY = 3, PosZ = 4, NegZ = 5 };

/// A point on the cube: face and texture coordinates in [0, 1].
struct CubeCoord {
  std::uint32_t face = 0;
  float u = 0.5f;
  float v = 0.5f;
};

/// The face and (t_u, t_v) that direction s (need not be unit, must not be zero) addresses.
[[nodiscard]] inline CubeCoord cube_coord(const vec3& s) {
  const float ax = std::abs(s.x), ay = std::abs(s.y), az = std::abs(s.z);
  float sc, tc, ma;
  std::uint32_t face;
  if (ax >= ay && ax >= az) {
    ma = ax;
    face = s.x >= 0.0f ? 0u : 1u;
    sc = s.x >= 0.0f ? -s.z : s.z;
    tc = -s.y;
  } else if (ay >= az) {
    ma = ay;
    face = s.y >= 0.0f ? 2u : 3u;
    sc = s.x;
    tc = s.y >= 0.0f ? s.z : -s.z;
  } else {
    ma = az;
    face = s.z >= 0.0f ? 4u : 5u;
    sc = s.z >= 0.0f ? s.x : -s.x;
    tc = -s.y;
  }
  return CubeCoord{face, 0.5f * (sc / ma + 1.0f), 0.5f * (tc / ma + 1.0f)};
}

/// The inverse: a direction (not normalised, major component ±1) through (u, v) on `face`.
[[nodiscard]] inline vec3 cube_direction(std::uint32_t face, float u, float v) {
  const float sc = 2.0f * u - 1.0f;
  const float tc = 2.0f * v - 1.0f;
  switch (face) {
  case 0: return vec3(1.0f, -tc, -sc);
  case 1: return vec3(-1.0f, -tc, sc);
  case 2: return vec3(sc, 1.0f, tc);
  case 3: return vec3(sc, -1.0f, -tc);
  case 4: return vec3(sc, -tc, 1.0f);
  default: return vec3(-sc, -tc, -1.0f);
  }
}

/// Texel index face·res² + row·res + column of the nearest texel (rows follow v).
[[nodiscard]] inline std::uint32_t texel_index(const CubeCoord& c, std::uint32_t resolution) {
  const float r = float(resolution);
  const std::uint32_t x = std::min(resolution - 1, std::uint32_t(std::max(0.0f, c.u * r)));
  const std::uint32_t y = std::min(resolution - 1, std::uint32_t(std::max(0.0f, c.v * r)));
  return (c.face * resolution + y) * resolution + x;
}

[[nodiscard]] inline std::uint32_t texel_of(const vec3& s, std::uint32_t resolution) {
  return texel_index(cube_coord(s), resolution);
}

/// Unit direction through the centre of texel `index`.
[[nodiscard]] inline vec3 texel_direction(std::uint32_t index, std::uint32_t resolution) {
  const std::uint32_t per_face = resolution * resolution;
  const std::uint32_t face = index / per_face;
  const std::uint32_t within = index % per_face;
  const float inv = 1.0f / float(resolution);
  return glm::normalize(cube_direction(face, (float(within % resolution) + 0.5f) * inv,
                                       (float(within / resolution) + 0.5f) * inv));
}

/// Largest angle (radians) between a texel's centre direction and any direction inside it: the
/// half-diagonal of a face-centre texel, where texels are largest, seen from the centre.
[[nodiscard]] inline float texel_half_angle(std::uint32_t resolution) {
  const float h = 1.0f / float(resolution); // half a texel in [-1, 1] face units
  return std::atan(h * std::sqrt(2.0f));
}

} // namespace specula::cache
