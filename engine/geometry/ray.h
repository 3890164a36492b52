#pragma once
/// \file
/// Rays and hits shared by every backend.

#include "specula/core/math.h"

#include <cstdint>
#include <limits>

namespace specula {

struct Ray {
  vec3 origin{0.0f};
  float tnear = 0.0f;
  vec3 direction{0.0f, 0.0f, -1.0f};
  float tfar = std::numeric_limits<float>::infinity();
};

inline constexpr std::uint32_t kNoSurface = 0xFFFFFFFFu;

/// A ray's closest hit. `surface` indexes the backend's surface table (kNoSurface: a miss);
/// `object_normal` is the geometric normal in the surface's object space, not normalised, facing
/// whichever way the triangle's winding says (Surface::world_normal turns it into world space:
/// resolving a hit stays cheap, only shaded hits pay for it); `uv` are the barycentrics of
/// vertices 1 and 2.
struct Hit {
  float t = std::numeric_limits<float>::infinity();
  std::uint32_t surface = kNoSurface;
  std::uint32_t primitive = 0;
  vec2 uv{0.0f};
  vec3 object_normal{0.0f};
  [[nodiscard]] bool hit() const { return surface != kNoSurface; }
};

} // namespace specula
