#version 460
// Wavefront, shadow rays: occlusion of the shadow rays the previous wave's shading emitted (or
// that used up a dispatch's budget: their walk was saved and goes on here, trace_pool.glsl).
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/frame_wavefront.glsl"

layout(local_size_x = 64) in;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= min(counters.shadow_queue_count[pc.parity], params.shadow_capacity)) return;
  uint s = shadow_queues[pc.parity * params.shadow_capacity + i];
  GpuShadowRay ray = shadows[s];
  uint slot = ray.status == kRayBudget ? ray.visible : kNoIndex;
  shadows[s].status = kRayPending;
  uint budget = params.budget;
  uint status = pool_trace(slot, ray.origin, ray.direction, 0.0, ray.tfar, true, budget);
  if (status == kRayDone) {
    atomicAdd(counters.rays[kKindShadow], 1u);
    shadows[s].visible = tr_occluded ? 0u : 1u;
    shadows[s].status = kRayDone;
  } else if (status == kRayBudget) {
    atomicAdd(counters.resumed, 1u);
    shadows[s].visible = pool_save(1u - pc.parity);
    shadows[s].status = kRayBudget;
    push_shadow(s);
  }
}
