#pragma once
#include "specula/core/math.h"

#include <cstdint>

namespace specula {

/// Written by transform_system: the entity's object-to-world matrix, and whether it changed in
/// the latest tick (the acceleration and cache-invalidation systems react to `moved`). In double:
/// world space may be far from the origin; the scene layer turns it into float render space
/// (camera-relative) for the tracers.
struct WorldTransform {
  dmat4 world_from_object{1.0};
  /// True when world_from_object changed in the last tick (or the entity is new).
  bool moved = true;
  /// Tick in which world_from_object last changed.
  std::uint64_t moved_tick = 0;
};

} // namespace specula
