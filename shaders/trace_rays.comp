// A batch of rays through the scene (VulkanTracer::intersect / occluded / intersect_camera): each
// invocation walks one ray for at most `budget` steps. A ray that finishes writes its hit (or its
// occlusion word) and kRayDone; one that runs out saves its traversal state and stack and writes
// kRayBudget, and the host dispatches again with `resume` set until none is left. Statuses are
// written only at this kernel's exits (into status_out, which the host clears before each
// dispatch): a ray still kRayPending was cut off by the driver (lavapipe's loop cap), and the
// next dispatch counts it in `cut`.
#version 460
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_basic : require

// Counting each ray's triangle tests (the grid resolution sweep's intersection work) costs a
// register per ray and a sum per subgroup, so only a pipeline specialised for it does.
layout(constant_id = 0) const bool kCountTests = false;
uint g_tests = 0u;
#define TRACE_ON_TRIANGLE() if (kCountTests) ++g_tests
// False for a BVH scene (VulkanTracer): the grid's walk compiled out.
layout(constant_id = 1) const bool kGridCode = true;
#define TRACE_GRID_CODE kGridCode
// False for a scene without a top level (VulkanTracer picks the pipeline per batch).
layout(constant_id = 2) const bool kTopCode = true;
#define TRACE_TOP_CODE kTopCode

#include "include/trace.glsl"

layout(local_size_x = 64) in;

layout(push_constant) uniform Push {
  uint ray_count;
  uint budget;       // traversal steps per ray in this dispatch
  uint any_hit;      // 1: occlusion words instead of hits
  uint resume;       // 1: continue the rays whose status_in is kRayBudget
  uint stack_stride; // saved stack entries per ray
} pc;

layout(set = 0, binding = 8) uniform usamplerBuffer rays_t; // two RGBA32UI texels per GpuRay
layout(std430, set = 0, binding = 9) writeonly buffer Hits { GpuHit hits[]; };
layout(std430, set = 0, binding = 10) writeonly buffer Occluded { uint occluded_words[]; };
layout(std430, set = 0, binding = 11) readonly buffer StatusIn { uint status_in[]; };
layout(std430, set = 0, binding = 12) writeonly buffer StatusOut { uint status_out[]; };
layout(std430, set = 0, binding = 13) buffer States { GpuTraceState states[]; };
layout(std430, set = 0, binding = 14) buffer Stacks { uvec2 stacks[]; };
layout(std430, set = 0, binding = 15) buffer Counters { TraceCounters counters; };

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= pc.ray_count) return;
  uvec4 ray_a = texelFetch(rays_t, int(2u * i));
  uvec4 ray_b = texelFetch(rays_t, int(2u * i + 1u));
  GpuRay ray;
  ray.origin = uintBitsToFloat(ray_a.xyz);
  ray.tnear = uintBitsToFloat(ray_a.w);
  ray.direction = uintBitsToFloat(ray_b.xyz);
  ray.tfar = uintBitsToFloat(ray_b.w);
  bool any_hit = pc.any_hit != 0u;

  // ---- Start or resume ---------------------------------------------------------------------------
  if (pc.resume == 0u) {
    trace_begin(ray.origin, ray.direction, ray.tnear, ray.tfar, any_hit);
  } else {
    uint status = status_in[i];
    if (status == kRayDone) {
      status_out[i] = kRayDone;
      return;
    }
    if (status == kRayPending) { // cut off in the previous dispatch: its state is lost
      atomicAdd(counters.cut, 1u);
      status_out[i] = kRayDone;
      return;
    }
    tr = states[i];
    uint base = i * pc.stack_stride;
    for (uint k = 0u; k < tr.sp; ++k) tr_stack[k] = stacks[base + k];
    trace_resume(ray.origin, ray.direction, ray.tnear, any_hit);
  }

  // ---- Walk --------------------------------------------------------------------------------------
  uint budget = pc.budget;
  uint status = trace_run(budget);
  // One atomic per subgroup, into its workgroup's step slot (TraceCounters).
  uint steps = subgroupAdd(pc.budget - budget);
  uint tests = kCountTests ? subgroupAdd(g_tests) : 0u;
  if (subgroupElect()) {
    atomicAdd(counters.steps[(gl_WorkGroupID.x % kStepSlots) * kStepSlotStride], steps);
    if (kCountTests) atomicAdd(counters.tests, tests);
  }

  // ---- Exits -------------------------------------------------------------------------------------
  if (status == kRayPending) return; // cut off by the driver: left pending, counted by the host
  if (status == kRayBudget) {
    tr.tfar = tr_world.tfar;
    states[i] = tr;
    uint base = i * pc.stack_stride;
    for (uint k = 0u; k < tr.sp; ++k) stacks[base + k] = tr_stack[k];
    atomicAdd(counters.budget, 1u);
    status_out[i] = kRayBudget;
    return;
  }
  if (any_hit)
    occluded_words[i] = tr_occluded ? 1u : 0u;
  else
    hits[i] = trace_result();
  status_out[i] = kRayDone;
}
