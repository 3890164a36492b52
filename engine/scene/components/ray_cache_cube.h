#pragma once
#include <cstdint>

namespace specula {

/// Requests a per-object ray-cache cube (Ruff, Clua, Fernandes 2013): six square faces of
/// `resolution`² texels caching the colour of rays that leave the object, indexed by direction.
/// Only meaningful on reflective or refractive entities. Storage arrives with the ray-cache work.
struct RayCacheCube {
  std::uint32_t resolution = 64;
  friend bool operator==(const RayCacheCube&, const RayCacheCube&) = default;
};

} // namespace specula
