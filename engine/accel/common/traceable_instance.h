#pragma once
/// \file
/// Which instances a two-level structure may hold (every backend asks the same question). An
/// instance is traced in its object space through the inverse of its transform; a transform that
/// is singular or nearly so (a scale of 0, which animations use to make objects vanish, or 1e-20)
/// has no usable inverse, and its world bounds collapse to a point. Embree asserts on both
/// (`diag[dim] > 0` in the top-level builder, `ray.valid()` on the object-space ray), and a float
/// inverse turns rays into Inf/NaN. Such an instance covers no pixel at any distance float can
/// resolve, so it is left out of the top level: invisible, counted in
/// TracerUpdateStats::hidden_instances. docs/design/robustness.md states the bounds.

#include "specula/core/math.h"

#include <algorithm>
#include <cmath>
#include <span>

namespace specula::accel {

/// The smallest |det| of a traceable instance's linear part (in double). Embree inverts the
/// transform in float as adjoint / det: det must stay a normal float with margin; 1e-30 is a
/// uniform scale of 1e-10.
inline constexpr double kMinInstanceDeterminant = 1e-30;
/// The largest entry of a traceable instance's object_from_world. Object-space ray origins are
/// object_from_world · render-space origin: render-space coordinates stay within a few times
/// kMaxCoordinate (1e12, core/math.h), so they stay below about 1e31, finite in float with room
/// for the intersector's arithmetic (and still below 3e37 for coordinates up to 1e19).
inline constexpr double kMaxInstanceInverse = 1e18;
/// World bounds thinner than this fraction of their largest coordinate (about 8 float ULPs) have
/// collapsed to a point in float: the geometry has no extent left to hit.
inline constexpr float kMinInstanceRelativeExtent = 0x1p-20f;

/// The upper-left 3×3 of an affine transform, in double.
[[nodiscard]] inline glm::dmat3 linear_part(const mat4& m) {
  return glm::dmat3(glm::dvec3(m[0]), glm::dvec3(m[1]), glm::dvec3(m[2]));
}

/// object_from_world of an affine world_from_object, inverted in double and rounded once to float
/// (glm's float inverse rounds its cofactors and determinant in float). Only for traceable
/// instances: a singular matrix gives Inf/NaN.
[[nodiscard]] inline glm::dmat4 inverse_affine(const mat4& world_from_object) {
  const glm::dmat3 inv = glm::inverse(linear_part(world_from_object));
  const glm::dvec3 t = -(inv * glm::dvec3(vec3(world_from_object[3])));
  return glm::dmat4(glm::dvec4(inv[0], 0.0), glm::dvec4(inv[1], 0.0), glm::dvec4(inv[2], 0.0),
                    glm::dvec4(t, 1.0));
}

/// Whether an instance of geometry with object-space bounds `object_bounds` (over the vertices its
/// triangles use) placed by `world_from_object` can be traced: its transform finite and affine, its
/// linear part invertible with a bounded inverse, its world bounds finite and not collapsed. An
/// empty mesh is not traceable either (nothing to hit).
[[nodiscard]] inline bool traceable_instance(const mat4& world_from_object,
                                             const Aabb& object_bounds) {
  if (!is_finite(world_from_object)) return false;
  if (world_from_object[0][3] != 0.0f || world_from_object[1][3] != 0.0f ||
      world_from_object[2][3] != 0.0f || world_from_object[3][3] != 1.0f)
    return false;
  if (object_bounds.empty() || !is_finite(object_bounds.min) || !is_finite(object_bounds.max))
    return false;
  const glm::dmat3 l = linear_part(world_from_object);
  const double det = glm::determinant(l);
  if (!(std::abs(det) >= kMinInstanceDeterminant)) return false;
  const glm::dmat3 inv = glm::inverse(l);
  for (int c = 0; c < 3; ++c)
    for (int r = 0; r < 3; ++r)
      if (!(std::abs(inv[c][r]) <= kMaxInstanceInverse)) return false;
  const Aabb world = object_bounds.transformed(world_from_object);
  if (!is_finite(world.min) || !is_finite(world.max)) return false;
  const vec3 extent = world.extent();
  const float largest_extent = std::max(extent.x, std::max(extent.y, extent.z));
  const vec3 magnitude = glm::max(glm::abs(world.min), glm::abs(world.max));
  const float largest_coordinate = std::max(magnitude.x, std::max(magnitude.y, magnitude.z));
  return largest_extent > 0.0f && largest_extent >= kMinInstanceRelativeExtent * largest_coordinate;
}

/// Object-space bounds of the vertices that `triangles` use (unused vertices do not count: the
/// backends' own structures never see them).
[[nodiscard]] inline Aabb used_vertex_bounds(std::span<const vec3> positions,
                                             std::span<const uvec3> triangles) {
  Aabb b;
  for (const uvec3& t : triangles)
    for (int k = 0; k < 3; ++k) b.grow(positions[t[k]]);
  return b;
}

} // namespace specula::accel
