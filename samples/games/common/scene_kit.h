#pragma once
/// \file
/// Small helpers the games build their scenes with, and the bounding volumes their collision
/// rules use (from the meshes' own bounds).

#include <specula/core/math.h>
#include <specula/ecs/registry.h>
#include <specula/scene/components.h>

#include <string>

namespace specula::games {

/// A built-in primitive ("sphere", "box", "plane", "cylinder"): radius for the round ones, size
/// for box and plane, height for the cylinder.
[[nodiscard]] MeshSource primitive(const std::string& name, float radius = 1.0f,
                                   vec3 size = vec3(1.0f), float height = 1.0f);

[[nodiscard]] Transform at(const dvec3& translation, const quat& rotation = quat(1, 0, 0, 0),
                           const vec3& scale = vec3(1.0f));

/// An entity with a Transform and, when `parent` is not null, a Parent.
ecs::Entity add_node(ecs::Registry& reg, const Transform& t, Kinematics::Type kinematics,
                     ecs::Entity parent = ecs::null_entity);
/// add_node plus the primitive's mesh and a material.
ecs::Entity add_mesh(ecs::Registry& reg, const MeshSource& source, const Transform& t,
                     const Material& m, Kinematics::Type kinematics,
                     ecs::Entity parent = ecs::null_entity);

/// The world matrix from the Transforms along the Parent chain: what transform_system computes
/// in the next tick, needed by a game now, for this step's rules.
[[nodiscard]] dmat4 world_of(ecs::Registry& reg, ecs::Entity e);

/// The closest point to `p` on the box `local` placed by world_from_object (an oriented box; the
/// matrix is rigid times an axis scale). Inside the box: the closest point on its surface, and
/// `inside` is set.
[[nodiscard]] dvec3 closest_on_box(const dmat4& world_from_object, const Aabb& local,
                                   const dvec3& p, bool& inside);

} // namespace specula::games
