#pragma once
/// \file
/// World transforms from the Transform/Parent hierarchy. Used by transform_system each tick and
/// by loaders once after loading.

#include "specula/ecs/registry.h"

#include <cstdint>
#include <string>

namespace specula {

/// How messages name an entity: its Name in double quotes ("arm"), or "entity 7" (its slot
/// index) when it has no Name or an empty one.
[[nodiscard]] std::string entity_label(const ecs::Registry& registry, ecs::Entity e);

/// Recomputes WorldTransform for every entity with a Transform (adding WorldTransform where
/// missing), parents before children. Sets `moved` (and `moved_tick = tick`) on exactly the
/// entities whose world matrix differs from the previous one, or that are new. Returns the number
/// of moved entities. Throws specula::Error (`context` names the scene) when a Parent is stale or
/// has no Transform, or when parents form a cycle: the one place cycles are checked, for every
/// scene format (load_scene) and every tick (transform_system). The message names the cycle's
/// entities in parent order from the one created first: `parent chain forms a cycle: "a" -> "c"
/// -> "b" -> "a"`. O(n) for any hierarchy shape, without recursion.
std::size_t update_world_transforms(ecs::Registry& registry, std::uint64_t tick,
                                    const std::string& context = "scene");

} // namespace specula
