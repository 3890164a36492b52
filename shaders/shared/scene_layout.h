// Flat scene tables shared by the CPU and the GPU: the scene layer (engine/render/scene_layer.h)
// fills arrays of these structs, and the Vulkan path will upload the same arrays as storage
// buffers. Included by C++ and by GLSL (std430): every struct is a whole number of 16-byte rows, a
// vec3 is always followed by one 4-byte scalar (std430 packs it into the vec3's fourth slot), and
// the C++ side checks each offset with static_assert. Geometry arrays (positions, normals,
// triangles) are tightly packed floats/uints (GLSL reads them as float[] / uint[] with 3·i).
#ifndef SPECULA_SHARED_SCENE_LAYOUT_H
#define SPECULA_SHARED_SCENE_LAYOUT_H

#ifdef __cplusplus
#include <glm/glm.hpp>

#include <cstddef>
#include <cstdint>

namespace specula::gpu {
using uint = std::uint32_t;
using vec3 = glm::vec3;
using vec4 = glm::vec4;
using mat4 = glm::mat4;
#define SPECULA_CONST inline constexpr
#else
#define SPECULA_CONST const
#endif

SPECULA_CONST uint kNoIndex = 0xFFFFFFFFu;

// GpuInstance::flags
SPECULA_CONST uint kInstanceStatic = 1u;    // part of the static set (mesh baked in world space)
SPECULA_CONST uint kInstanceDeforming = 2u; // owns its vertex range, rewritten when it deforms
SPECULA_CONST uint kInstanceIdentity = 4u;  // world_from_object is the identity (baked)
SPECULA_CONST uint kInstanceSmooth = 8u;    // its mesh's vertex normals may be interpolated

// GpuInstance::kinematics (Kinematics::Type)
SPECULA_CONST uint kKinematicsStatic = 0u;
SPECULA_CONST uint kKinematicsHierarchical = 1u;
SPECULA_CONST uint kKinematicsFree = 2u;

// GpuLight::type (Light::Type)
SPECULA_CONST uint kLightPoint = 0u;
SPECULA_CONST uint kLightDirectional = 1u;
SPECULA_CONST uint kLightSpot = 2u;

/// A range of the geometry pools: vertices [first_vertex, +vertex_count) of the positions pool
/// (and, unless first_normal is kNoIndex, of the normals pool from first_normal), triangles
/// [first_triangle, +triangle_count) whose indices are relative to first_vertex. Object-space
/// bounds of the positions.
struct GpuMesh {
  uint first_vertex;
  uint vertex_count;
  uint first_triangle;
  uint triangle_count;
  uint first_normal;
  uint _pad0;
  uint _pad1;
  uint _pad2;
  vec3 bounds_min;
  float _pad3;
  vec3 bounds_max;
  float _pad4;
};

/// Material of one instance (Material component; see engine/scene/components/material.h).
struct GpuMaterial {
  vec3 base_color;
  float ior;
  vec3 emission;
  float reflectivity;
  float transmission;
  float roughness;
  uint _pad0;
  uint _pad1;
};

/// One placed mesh: an entity with Mesh and WorldTransform. normal_from_object holds the columns
/// of the inverse transpose of world_from_object's upper 3×3 (w unused). Static instances point at
/// a mesh baked in world space and carry the identity; world_bounds are their world-space bounds
/// either way.
struct GpuInstance {
  mat4 world_from_object;
  vec4 normal_from_object[3];
  uint mesh;
  uint material;
  uint entity_index;
  uint entity_generation;
  uint flags;
  uint kinematics;
  uint _pad0;
  uint _pad1;
  vec3 world_bounds_min;
  float _pad2;
  vec3 world_bounds_max;
  float _pad3;
};

/// A punctual light in world space (KHR_lights_punctual conventions, engine/trace/lights.h).
struct GpuLight {
  vec3 position;
  uint type;
  vec3 direction; // where the light points (directional, spot)
  float range;    // 0: unlimited
  vec3 intensity; // colour × intensity
  float cos_inner;
  float cos_outer;
  uint _pad0;
  uint _pad1;
  uint _pad2;
};

#ifdef __cplusplus
static_assert(sizeof(GpuMesh) == 64 && offsetof(GpuMesh, bounds_min) == 32 &&
              offsetof(GpuMesh, bounds_max) == 48);
static_assert(sizeof(GpuMaterial) == 48 && offsetof(GpuMaterial, ior) == 12 &&
              offsetof(GpuMaterial, emission) == 16 && offsetof(GpuMaterial, reflectivity) == 28 &&
              offsetof(GpuMaterial, transmission) == 32);
static_assert(sizeof(GpuInstance) == 176 && offsetof(GpuInstance, normal_from_object) == 64 &&
              offsetof(GpuInstance, mesh) == 112 && offsetof(GpuInstance, flags) == 128 &&
              offsetof(GpuInstance, world_bounds_min) == 144 &&
              offsetof(GpuInstance, world_bounds_max) == 160);
static_assert(sizeof(GpuLight) == 64 && offsetof(GpuLight, type) == 12 &&
              offsetof(GpuLight, direction) == 16 && offsetof(GpuLight, range) == 28 &&
              offsetof(GpuLight, intensity) == 32 && offsetof(GpuLight, cos_outer) == 48);
static_assert(sizeof(GpuMesh) % 16 == 0 && sizeof(GpuMaterial) % 16 == 0 &&
              sizeof(GpuInstance) % 16 == 0 && sizeof(GpuLight) % 16 == 0);
} // namespace specula::gpu
#endif

#undef SPECULA_CONST
#endif // SPECULA_SHARED_SCENE_LAYOUT_H
