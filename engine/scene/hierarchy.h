#pragma once
/// \file
/// World transforms from the Transform/Parent hierarchy. Used by transform_system each tick and
/// by loaders once after loading.

#include "specula/core/math.h"
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

/// "(x, y, z)" with each coordinate's shortest round-trip text, for messages.
[[nodiscard]] std::string format_position(const dvec3& p);

/// How messages name an entity: its Name in double quotes ("arm"), or "entity 7" (its slot
/// index) when it has no Name or an empty one.
[[nodiscard]] std::string entity_label(const ecs::Registry& registry, ecs::Entity e);

/// Recomputes WorldTransform for every entity with a Transform (adding WorldTransform where
/// missing), parents before children. Sets `moved` (and `moved_tick = tick`) on exactly the
/// entities whose world matrix differs from the previous one, or that are new. Returns the number
/// of moved entities and lists them in the TransformChanges resource. Throws specula::Error
/// (`context` names the scene) when a Parent is stale or has no Transform, when an entity's world
/// position (its matrix's translation, composed in double) is not finite or lies outside
/// ±kMaxCoordinate (naming the entity), or when parents form a cycle: the one place cycles are
/// checked, for every scene format (load_scene) and every tick (transform_system). The message
/// names the cycle's entities in parent order from the one created first: `parent chain forms a
/// cycle: "a" -> "c" -> "b" -> "a"`. O(n) for any hierarchy shape, without recursion.
std::size_t update_world_transforms(ecs::Registry& registry, std::uint64_t tick,
                                    const std::string& context = "scene");

} // namespace specula
