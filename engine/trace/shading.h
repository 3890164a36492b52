#pragma once
/// \file
/// Surface geometry at a hit, read from the scene layer's flat tables, and how a Whitted hit
/// continues (reflection and refraction weights and directions). Shared by every integrator.

#include "specula/geometry/ray.h"
#include "specula/geometry/ray_offset.h"
#include "specula/render/scene_layer.h"
#include "specula/trace/lights.h"
#include "specula/trace/optics.h"

#include <algorithm>
#include <cmath>
#include <optional>

namespace specula {

struct ShadingPoint {
  vec3 position; ///< the hit, where lights are evaluated
  /// Where secondary rays leave from, before offset_ray_origin moves them off the surface: the hit
  /// pulled inside its triangle by kEdgeInset × its error bound (inset_barycentrics), so that a
  /// hit rounded onto a concave edge does not start behind the neighbouring face.
  vec3 spawn_point;
  vec3 spawn_error;      ///< bound on the rounding error of spawn_point (ray_offset.h)
  vec3 geometric_normal; ///< facing the incoming ray
  vec3 shading_normal;   ///< facing the same side as geometric_normal
  bool front_face;       ///< the ray hit the side the triangle's winding faces (entering)
};

[[nodiscard]] inline mat3 normal_matrix(const gpu::GpuInstance& inst) {
  return mat3(vec3(inst.normal_from_object[0]), vec3(inst.normal_from_object[1]),
              vec3(inst.normal_from_object[2]));
}

/// Hit position from barycentrics on the triangle (more accurate than origin + t·d far from the
/// ray origin), normals oriented towards the incoming direction. Instances baked in world space
/// (kInstanceIdentity) skip the transforms; the results equal those of an identity transform.
[[nodiscard]] inline ShadingPoint shading_point(const SceneTables& tables, const Hit& hit,
                                                const vec3& direction,
                                                bool with_error_bound = true) {
  const gpu::GpuInstance& inst = tables.instances[hit.instance];
  const gpu::GpuMesh& mesh = tables.meshes[inst.mesh];
  const uvec3 tri = tables.triangles[mesh.first_triangle + hit.primitive];
  const vec3* positions = tables.positions.data() + mesh.first_vertex;
  const float w = 1.0f - hit.uv.x - hit.uv.y;
  const vec3& p0 = positions[tri.x];
  const vec3& p1 = positions[tri.y];
  const vec3& p2 = positions[tri.z];
  const vec3 p_object = w * p0 + hit.uv.x * p1 + hit.uv.y * p2;
  const bool identity = (inst.flags & gpu::kInstanceIdentity) != 0;
  const mat4& m = inst.world_from_object;
  ShadingPoint sp;
  sp.position = identity ? p_object : vec3(m * vec4(p_object, 1.0f));
  if (with_error_bound && identity) {
    const SpawnPoint spawn = spawn_point(p0, p1, p2, hit.uv.x, hit.uv.y);
    sp.spawn_point = spawn.point;
    sp.spawn_error = spawn.error;
  } else if (with_error_bound) {
    // spawn_point's steps through the transform: the inset in world space, where the neighbouring
    // faces are; the points interpolated in object space and transformed, as the hit.
    const auto error_at = [&](const vec3& b, const vec3& q) {
      return transformed_error(m, q, barycentric_error(p0, p1, p2, b.x, b.y, b.z));
    };
    const vec3 hit_error = error_at(vec3(w, hit.uv.x, hit.uv.y), p_object);
    const vec3 b = inset_barycentrics(vec3(m * vec4(p0, 1.0f)), vec3(m * vec4(p1, 1.0f)),
                                      vec3(m * vec4(p2, 1.0f)), hit.uv.x, hit.uv.y,
                                      kEdgeInset * glm::length(hit_error));
    if (b == vec3(w, hit.uv.x, hit.uv.y)) {
      sp.spawn_point = sp.position;
      sp.spawn_error = hit_error;
    } else {
      const vec3 q_object = b.x * p0 + b.y * p1 + b.z * p2;
      sp.spawn_point = vec3(m * vec4(q_object, 1.0f));
      sp.spawn_error = error_at(b, q_object);
    }
  } else {
    sp.spawn_point = sp.position;
    sp.spawn_error = vec3(0.0f);
  }
  const mat3 n_from_o = normal_matrix(inst);
  const vec3 normal = glm::normalize(identity ? hit.object_normal : n_from_o * hit.object_normal);
  sp.front_face = glm::dot(normal, direction) < 0.0f;
  sp.geometric_normal = sp.front_face ? normal : -normal;
  sp.shading_normal = sp.geometric_normal;
  if ((inst.flags & gpu::kInstanceSmooth) != 0 && mesh.first_normal != gpu::kNoIndex) {
    const vec3* n = tables.normals.data() + mesh.first_normal;
    const vec3 n_object = w * n[tri.x] + hit.uv.x * n[tri.y] + hit.uv.y * n[tri.z];
    vec3 ns = identity ? n_object : n_from_o * n_object;
    const float len = glm::length(ns);
    if (len > 0.0f && std::isfinite(len)) {
      ns /= len;
      sp.shading_normal = glm::dot(ns, sp.geometric_normal) < 0.0f ? -ns : ns;
    }
  }
  return sp;
}

/// How a Whitted hit continues: mirror reflection with the material's reflectivity plus the
/// Fresnel-reflected part of its transmission; refraction with the rest (none on total internal
/// reflection). Directions are unit and leave on the correct side of the geometric surface even
/// where the interpolated shading normal disagrees with it.
struct SpecularSplit {
  float reflect_weight = 0.0f;
  vec3 reflect_direction{0.0f};
  float refract_weight = 0.0f;
  vec3 refract_direction{0.0f};
};

[[nodiscard]] inline SpecularSplit split_specular(const gpu::GpuMaterial& m, const ShadingPoint& sp,
                                                  const vec3& d) {
  SpecularSplit split;
  split.reflect_weight = m.reflectivity;
  if (m.transmission > 0.0f) {
    const float eta = sp.front_face ? 1.0f / m.ior : m.ior;
    float cos_i = -glm::dot(d, sp.shading_normal);
    std::optional<vec3> t = refract_direction(d, sp.shading_normal, eta);
    // The refracted ray must cross the geometric surface; where the shading normal bends it back,
    // refract about the geometric normal instead.
    if (t && glm::dot(*t, sp.geometric_normal) >= 0.0f) {
      t = refract_direction(d, sp.geometric_normal, eta);
      cos_i = -glm::dot(d, sp.geometric_normal);
    }
    if (t) {
      const float f = fresnel_dielectric(cos_i, eta);
      split.reflect_weight += m.transmission * f;
      split.refract_weight = m.transmission * (1.0f - f);
      split.refract_direction = *t;
    } else {
      split.reflect_weight += m.transmission; // total internal reflection
    }
  }
  if (split.reflect_weight > 0.0f) {
    vec3 r = reflect_direction(d, sp.shading_normal);
    if (glm::dot(r, sp.geometric_normal) <= 0.0f) r = reflect_direction(d, sp.geometric_normal);
    split.reflect_direction = glm::normalize(r);
  }
  return split;
}

[[nodiscard]] inline float max_component(const vec3& v) {
  return std::max(v.x, std::max(v.y, v.z));
}

/// The weight of a material's diffuse (Lambert) part: what reflection and transmission leave.
[[nodiscard]] inline float diffuse_weight(const gpu::GpuMaterial& m) {
  return std::max(0.0f, 1.0f - m.reflectivity - m.transmission);
}

/// How far a shadow ray from `origin` towards `light` (sampled as `ls` from the shading point)
/// goes: to just short of the light, so that a light placed on a surface does not shadow itself;
/// forever towards a directional light.
[[nodiscard]] inline float shadow_tfar(const gpu::GpuLight& light, const LightSample& ls,
                                       const vec3& origin) {
  return std::isinf(ls.distance)
             ? ls.distance
             : float(glm::length(glm::dvec3(light.position - origin)) * (1.0 - 1e-5));
}

/// punctual_shadow_ray once the light is sampled (towards `to_light`, `irradiance` at normal
/// incidence; `tfar()` the ray's far distance, asked only for a ray that is emitted).
template <class Tfar, class Emit>
inline void lit_shadow_ray(const vec3& to_light, const vec3& irradiance, Tfar&& tfar,
                           const ShadingPoint& sp, const vec3& albedo, Emit&& emit) {
  if (glm::dot(to_light, sp.geometric_normal) <= 0.0f) return; // behind
  const float cos_theta = glm::dot(to_light, sp.shading_normal);
  if (cos_theta <= 0.0f || max_component(irradiance) <= 0.0f) return;
  emit(to_light, tfar(), albedo * irradiance * cos_theta);
}

/// The shadow ray from shading point `sp` (leaving from `origin`, its offset spawn point) towards
/// `light`, for a diffuse part of reflectance `albedo`: `emit(direction, tfar, value)` with the
/// ray's direction and far distance and the radiance it brings when nothing blocks it (albedo ×
/// irradiance × cos θ); nothing when the light cannot light it (behind the surface, at or past
/// grazing, or black). Whitted's and the shadow caster's local shading both use it, so that they
/// give the same bits. The parts go to `emit` as values for it to store where the ray belongs:
/// a ray put together here and copied there was read back before its parts had reached memory,
/// a stall on every shadow ray.
template <class Emit>
inline void punctual_shadow_ray(const gpu::GpuLight& light, const ShadingPoint& sp,
                                const vec3& origin, const vec3& albedo, Emit&& emit) {
  const LightSample ls = sample_light(light, sp.position);
  lit_shadow_ray(
      ls.to_light, ls.irradiance, [&] { return shadow_tfar(light, ls, origin); }, sp, albedo, emit);
}

/// Stores a ray part by part (see punctual_shadow_ray).
inline void store_ray(Ray& ray, const vec3& origin, const vec3& direction, float tfar) {
  ray.origin = origin;
  ray.tnear = 0.0f;
  ray.direction = direction;
  ray.tfar = tfar;
}

} // namespace specula
