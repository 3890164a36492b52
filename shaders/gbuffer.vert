#version 460
// Hybrid mode's raster pass (engine/gpu/raster_primary.h): one draw per instance slot
// (gl_InstanceIndex), three vertices per triangle of its mesh, pulled from the scene's pools and
// placed by its world_from_object. The projection is the camera's (trace/camera_rays.h) in render
// space: x = d·right / |right|², y = −d·up / |up|² (row 0 at the top), w = d·forward, so a pixel
// centre covers what its primary ray meets; z = near gives reversed depth (near / distance).
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "shared/scene_layout.h"

layout(std430, set = 0, binding = 0) readonly buffer ScenePositions { float positions[]; };
layout(std430, set = 0, binding = 1) readonly buffer SceneTriangles { uint triangles[]; };
layout(std430, set = 0, binding = 2) readonly buffer SceneMeshes { GpuMesh meshes[]; };
layout(std430, set = 0, binding = 3) readonly buffer SceneInstances { GpuInstance instances[]; };

layout(push_constant) uniform RasterPush {
  vec4 origin;  // w: the near plane's distance
  vec4 right;   // right / |right|²
  vec4 up;      // up / |up|²
  vec4 forward; // unit
} pc;

layout(location = 0) flat out uvec2 ids;

void main() {
  uint slot = uint(gl_InstanceIndex);
  GpuInstance inst = instances[slot];
  GpuMesh mesh = meshes[inst.mesh];
  uint tri = uint(gl_VertexIndex) / 3u;
  uint k = uint(gl_VertexIndex) - 3u * tri;
  uint v = mesh.first_vertex + triangles[3u * (mesh.first_triangle + tri) + k];
  vec3 p = vec3(positions[3u * v], positions[3u * v + 1u], positions[3u * v + 2u]);
  vec3 d = (inst.world_from_object * vec4(p, 1.0)).xyz - pc.origin.xyz;
  gl_Position = vec4(dot(d, pc.right.xyz), -dot(d, pc.up.xyz), pc.origin.w, dot(d, pc.forward.xyz));
  // Flat: the provoking (first) vertex's value, the same for the triangle's three.
  ids = uvec2(slot, tri);
}
