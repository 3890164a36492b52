#pragma once
/// \file
/// World transforms from the Transform/Parent hierarchy. Used by transform_system each tick and
/// by loaders once after loading.

#include "specula/ecs/registry.h"

#include <cstdint>
#include <string>
#include <vector>

namespace specula {

/// A registry resource written by every update_world_transforms: the entities whose world
/// transform changed in that update (new ones included), in parents-first order. `sequence` grows
/// by one per update, so a consumer that last saw sequence n − 1 may take `moved` as everything
/// that moved since; any other gap (or no resource) means it must look at every entity.
struct TransformChanges {
  std::uint64_t sequence = 0;
  std::uint64_t tick = 0;
  std::vector<ecs::Entity> moved;
};

/// Recomputes WorldTransform for every entity with a Transform (adding WorldTransform where
/// missing), parents before children. Sets `moved` (and `moved_tick = tick`) on exactly the
/// entities whose world matrix differs from the previous one, or that are new. Returns the number
/// of moved entities and lists them in the TransformChanges resource. Throws specula::Error when a
/// Parent is stale, has no Transform, or forms a cycle (`context` names the scene for the message).
std::size_t update_world_transforms(ecs::Registry& registry, std::uint64_t tick,
                                    const std::string& context = "scene");

} // namespace specula
