// Test kernel (tests/gpu/test_gpu_kernels.cpp): the cells trace.glsl's 3D-DDA enters for each ray,
// in order, to compare with UniformGrid::traverse's. The walk is trace.glsl's own (a closest-hit
// trace over the scene's grid), only observed through its TRACE_ON_CELL hook.
#version 460
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"

void probe_cell(uint c);
#define TRACE_ON_CELL(c) probe_cell(c)
#include "include/trace.glsl"

layout(local_size_x = 8) in;

layout(push_constant) uniform Push {
  uint ray_count;
  uint budget;    // walk steps per ray (the whole walk must fit: the test asserts kRayDone)
  uint max_cells; // cells recorded per ray
} pc;

layout(std430, set = 0, binding = 8) readonly buffer Rays { GpuRay rays[]; };
layout(std430, set = 0, binding = 9) writeonly buffer Cells { uint cells[]; };
// Per ray: the status (written only at this kernel's exit) and the number of cells entered.
layout(std430, set = 0, binding = 10) writeonly buffer Walks { uvec2 walks[]; };

uint g_ray;
uint g_count;

void probe_cell(uint c) {
  if (g_count < pc.max_cells) cells[g_ray * pc.max_cells + g_count] = c;
  ++g_count;
}

void main() {
  g_ray = gl_GlobalInvocationID.x;
  if (g_ray >= pc.ray_count) return;
  g_count = 0u;
  GpuRay ray = rays[g_ray];
  trace_begin(ray.origin, ray.direction, ray.tnear, ray.tfar, false);
  uint budget = pc.budget;
  uint status = trace_run(budget);
  if (status == kRayPending) return; // cut by the driver: left pending
  walks[g_ray] = uvec2(status, g_count);
}
