#pragma once
/// \file
/// Which Kinematics an entity's motion needs, decided in one place for every scene format
/// (load_scene settles it once after loading) and for the accelerators, which ask per entity.

#include "specula/ecs/registry.h"
#include "specula/scene/components/kinematics.h"

#include <string>

namespace specula {

/// The kinematics the entity's animations call for:
///   Free — its own Animation has vertex keys (the mesh deforms, so its structure is refitted);
///   Hierarchical — its own Animation, or the Animation of an ancestor along its Parent chain,
///     has a translation, rotation or scale track (it moves rigidly: an instance of its mesh);
///   Static — nothing animates it.
/// An ancestor's vertex animation deforms that ancestor's mesh only and moves nothing; camera
/// paths move cameras, not meshes. The walk up the Parent chain stops at a stale parent and
/// after as many steps as the registry has live entities, so a cycle (which
/// update_world_transforms rejects) gives an answer rather than a hang. O(chain length), allocates
/// nothing.
[[nodiscard]] Kinematics::Type inferred_kinematics(const ecs::Registry& registry, ecs::Entity e);

/// The spelling of a kinematics type in scene files and messages: "static", "hierarchical" or
/// "free".
[[nodiscard]] const char* kinematics_name(Kinematics::Type type);

/// Settles Kinematics after loading (load_scene calls it once, after update_world_transforms has
/// validated the hierarchy, for every format):
///   - an explicit Kinematics (stated by the file), on any entity, is checked against the
///     animations: "static" on an entity that an animation moves, or anything but "free" on one
///     with vertex animation, is a specula::Error naming `source`, the entity (by Name) and what
///     moves it — the acceleration structure would not follow the motion. More freedom than
///     needed ("free" on an entity nothing moves) is allowed;
///   - every entity with a Mesh and no Kinematics gets inferred_kinematics(). Entities without a
///     Mesh get none: no acceleration structure depends on them.
/// Linear in the number of entities for any hierarchy shape (ancestor lookups are memoised).
void settle_kinematics(ecs::Registry& registry, const std::string& source);

} // namespace specula
