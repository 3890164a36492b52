#pragma once
/// \file
/// The leaving-radiance hook: where the radiance that a secondary ray brings back to the object it
/// leaves is delivered, as its own value. A ray-cache cube (Ruff, Clua, Fernandes 2013) stores
/// exactly this — "the colour of rays that leave the object", indexed by direction — so the cache
/// work plugs in here; until then no hook is installed and integrators skip the bookkeeping.
///
/// The radiance of a leaving ray is everything it brings back: the local shading where it lands
/// plus, weighted, the radiance of the rays spawned there — nested leaving rays included (a sphere
/// seen in a sphere: the inner ray is delivered to the inner sphere, and its contribution is part
/// of the outer ray's radiance delivered to the outer one). A pixel is its primary hit's local
/// shading plus the sum over the rays leaving that hit of weight × radiance.

#include "specula/core/math.h"
#include "specula/ecs/entity.h"
#include "specula/trace/stats.h"

#include <cstdint>
#include <span>

namespace specula {

struct LeavingRadiance {
  ecs::Entity from;       ///< the entity the ray leaves
  std::uint32_t instance; ///< its scene-layer instance slot
  RayKind kind;           ///< Reflection or Refraction
  std::uint32_t depth;    ///< 1 for rays leaving a primary hit
  std::uint32_t pixel;    ///< y · width + x of the pixel it serves
  vec3 origin;            ///< world space
  vec3 direction;         ///< unit, world space
  vec3 weight;     ///< relative to the ray it was spawned by (its share of that ray's radiance)
  vec3 throughput; ///< relative to the pixel (product of weights along the path)
  vec3 radiance;   ///< what the ray brought back
};

class RadianceHook {
public:
  virtual ~RadianceHook() = default;
  /// Receives one tile's leaving rays once the tile's last wave is done, in a deterministic order
  /// (wave by wave, then trace order). Called from worker threads, several tiles at once:
  /// implementations synchronise, and apply what they store at frame end (frames stay
  /// deterministic whatever the thread count).
  virtual void leaving(std::span<const LeavingRadiance> rays) = 0;
};

} // namespace specula
