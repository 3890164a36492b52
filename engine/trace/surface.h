#pragma once
/// \file
/// What shading needs to know about the surface a ray hit, whatever backend found it.

#include "specula/core/math.h"
#include "specula/ecs/entity.h"
#include "specula/geometry/triangle_mesh.h"
#include "specula/scene/components/material.h"

namespace specula {

struct Surface {
  ecs::Entity entity = ecs::null_entity; ///< the entity the surface belongs to (rays leaving it carry it)
  Material material;
  /// Object-space geometry (triangles, normals). Baked static geometry is already in world space.
  const TriangleMesh* mesh = nullptr;
  /// Object-space vertex positions as traced (the deformed ones for deforming meshes).
  const vec3* positions = nullptr;
  mat4 world_from_object{1.0f};
  /// Takes object-space normals to world space (inverse transpose of world_from_object).
  mat3 world_normal_from_object{1.0f};
  /// Whether mesh->normals may be interpolated for shading (false for deformed meshes, whose
  /// vertex normals no longer match the positions: shading then uses the geometric normal).
  bool smooth_normals = true;

  /// Unit world-space normal from an object-space one (e.g. Hit::object_normal).
  [[nodiscard]] vec3 world_normal(const vec3& object_normal) const {
    return glm::normalize(world_normal_from_object * object_normal);
  }
};

} // namespace specula
