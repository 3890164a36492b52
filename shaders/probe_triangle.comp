// Test kernel (tests/gpu/test_gpu_kernels.cpp): ray_triangle.glsl's watertight test, one ray
// against one triangle per invocation, to compare with accel::intersect_watertight.
#version 460
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "shared/trace_layout.h"
#include "include/ray_triangle.glsl"

layout(local_size_x = 8) in;

layout(push_constant) uniform Push { uint count; } pc;

layout(std430, set = 0, binding = 0) readonly buffer Rays { GpuRay rays[]; };
// Three vertices per test, 9 floats.
layout(std430, set = 0, binding = 1) readonly buffer Triangles { float corners[]; };
// Per test: hit (1 or 0), then t, u, v as bits.
layout(std430, set = 0, binding = 2) writeonly buffer Results { uvec4 results[]; };

vec3 corner(uint i, uint k) {
  uint b = 9u * i + 3u * k;
  return vec3(corners[b], corners[b + 1u], corners[b + 2u]);
}

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= pc.count) return;
  GpuRay ray = rays[i];
  PreparedRay r = prepare_ray(ray.origin, ray.direction, ray.tnear, ray.tfar);
  float t, u, v;
  bool hit = intersect_watertight(r, corner(i, 0u), corner(i, 1u), corner(i, 2u), r.tfar, t, u, v);
  results[i] = uvec4(hit ? 1u : 0u, floatBitsToUint(t), floatBitsToUint(u), floatBitsToUint(v));
}
