// Tracing from any kernel: the scene's buffers at bindings [0, kSceneBindings) of set 0 and the
// two queries every kernel uses.
//
// CONTRACT (kept by every implementation; the streaming kernels rely on it):
//   uint trace_closest(vec3 org, vec3 dir, float tnear, float tfar, inout uint budget,
//                      inout GpuHit hit)
//   uint trace_any(vec3 org, vec3 dir, float tnear, float tfar, inout uint budget,
//                  out bool occluded)
// Both return kRayDone when finished (trace_closest: hit.instance != kNoIndex on a hit; trace_any:
// sets `occluded`) or kRayBudget when
// `budget` (loop iterations left to this invocation in this dispatch) ran out first.
//
// THIS FILE IS THE GROUNDWORK STUB: brute force over every instance and triangle, Möller–Trumbore.
// The BVH / grid traversal replaces its body, not its contract.
#ifndef SPECULA_TRACE_GLSL
#define SPECULA_TRACE_GLSL

#include "shared/scene_layout.h"
#include "shared/trace_layout.h"

layout(std430, set = 0, binding = 0) readonly buffer ScenePositions { float positions[]; };
layout(std430, set = 0, binding = 1) readonly buffer SceneTriangles { uint triangles[]; };
layout(std430, set = 0, binding = 2) readonly buffer SceneMeshes { GpuMesh meshes[]; };
layout(std430, set = 0, binding = 3) readonly buffer SceneInstances { GpuInstance instances[]; };
layout(std430, set = 0, binding = 4) readonly buffer SceneHeader { uint instance_count; };
layout(std430, set = 0, binding = 5) readonly buffer SceneUnused5 { uint unused5[]; };
layout(std430, set = 0, binding = 6) readonly buffer SceneUnused6 { uint unused6[]; };
layout(std430, set = 0, binding = 7) readonly buffer SceneUnused7 { uint unused7[]; };

vec3 scene_position(uint i) { return vec3(positions[3 * i], positions[3 * i + 1], positions[3 * i + 2]); }

// Returns true on a hit within (tnear, tmax); t, u, v out.
bool stub_triangle(vec3 org, vec3 dir, vec3 p0, vec3 p1, vec3 p2, float tnear, float tmax,
                   out float t, out float u, out float v) {
  t = 0.0; u = 0.0; v = 0.0;
  vec3 e1 = p1 - p0, e2 = p2 - p0;
  vec3 p = cross(dir, e2);
  float det = dot(e1, p);
  if (det == 0.0) return false;
  float inv_det = 1.0 / det;
  vec3 s = org - p0;
  u = dot(s, p) * inv_det;
  if (!(u >= 0.0) || u > 1.0) return false;
  vec3 q = cross(s, e1);
  v = dot(dir, q) * inv_det;
  if (!(v >= 0.0) || u + v > 1.0) return false;
  t = dot(e2, q) * inv_det;
  return t > tnear && t < tmax;
}

uint stub_trace(vec3 org, vec3 dir, float tnear, float tfar, inout uint budget, inout GpuHit hit,
                bool any_hit) {
  hit.instance = kNoIndex;
  hit.t = tfar;
  for (uint i = 0u; i < instance_count; ++i) {
    GpuInstance inst = instances[i];
    if (inst.mesh == kNoIndex) continue;
    GpuMesh mesh = meshes[inst.mesh];
    mat4 object_from_world = inverse(inst.world_from_object);
    vec3 o = (object_from_world * vec4(org, 1.0)).xyz;
    vec3 d = mat3(object_from_world) * dir;
    for (uint k = 0u; k < mesh.triangle_count; ++k) {
      if (budget == 0u) return kRayBudget;
      --budget;
      uint tri = 3u * (mesh.first_triangle + k);
      vec3 p0 = scene_position(mesh.first_vertex + triangles[tri]);
      vec3 p1 = scene_position(mesh.first_vertex + triangles[tri + 1u]);
      vec3 p2 = scene_position(mesh.first_vertex + triangles[tri + 2u]);
      float t, u, v;
      if (stub_triangle(o, d, p0, p1, p2, tnear, hit.t, t, u, v)) {
        hit.t = t; hit.u = u; hit.v = v; hit.instance = i; hit.primitive = k;
        vec3 ng = cross(p1 - p0, p2 - p0);
        hit.ng_x = ng.x; hit.ng_y = ng.y; hit.ng_z = ng.z;
        if (any_hit) return kRayDone;
      }
    }
  }
  if (hit.instance == kNoIndex) hit.t = 1.0 / 0.0;
  return kRayDone;
}

uint trace_closest(vec3 org, vec3 dir, float tnear, float tfar, inout uint budget, inout GpuHit hit) {
  return stub_trace(org, dir, tnear, tfar, budget, hit, false);
}

// occluded is set to true when anything lies within (tnear, tfar).
uint trace_any(vec3 org, vec3 dir, float tnear, float tfar, inout uint budget, out bool occluded) {
  GpuHit hit;
  uint status = stub_trace(org, dir, tnear, tfar, budget, hit, true);
  occluded = hit.instance != kNoIndex;
  return status;
}

#endif
