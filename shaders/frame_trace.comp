#version 460
// Wavefront, traversal + intersection of a wave's rays. A ray that uses up this dispatch's
// traversal budget saves its walk (trace_pool.glsl) and is queued for the next wave, which goes on
// from there.
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/frame_wavefront.glsl"

layout(local_size_x = 64) in;

// Out of budget: the walk saved into the next wave's pool, the node queued for that wave.
void requeue(uint n) {
  atomicAdd(counters.resumed, 1u);
  nodes[n].resume = pool_save(1u - pc.parity);
  nodes[n].status = kRayBudget;
  push_ray(n);
}

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= min(counters.queue_count[pc.parity], params.node_capacity)) return;
  uint n = queues[pc.parity * params.node_capacity + i];
  GpuFrameNode node = nodes[n];
  // Hybrid mode: frame_visibility.comp already found this primary ray's hit.
  if (node.status == kRayDone) return;
  uint slot = node.status == kRayBudget ? node.resume : kNoIndex;
  // Pending until one of the exits below: a ray still pending afterwards was cut by the driver.
  nodes[n].status = kRayPending;
  uint budget = params.budget;
  if (kCache && (node.answer & 15u) == kAnswerUseIfClear) {
    // A cached miss (Tau mode): the CPU's occlusion ray confirms nothing lies on the way; if
    // something does, the ray is traced after all (two rays for it, its radiance its own).
    uint confirm = pool_trace(slot, node.origin, node.direction, 0.0, kInfinity, true, budget);
    if (confirm == kRayBudget) {
      requeue(n);
      return;
    }
    if (confirm != kRayDone) return; // cut by the driver: left pending
    slot = kNoIndex;
    atomicAdd(counters.rays[kKindShadow], 1u);
    if (!tr_occluded) {
      nodes[n].answer = kAnswerUse | kAnswerLookedUp;
      nodes[n].rays = 1u;
      nodes[n].status = kRayDone;
      return;
    }
    nodes[n].answer = kAnswerTrace | kAnswerLookedUp;
    nodes[n].rays = 2u;
    nodes[n].radiance = vec3(0.0);
    nodes[n].seen = 0u;
  }
  uint status = pool_trace(slot, node.origin, node.direction, 0.0, node.tfar, false, budget);
  if (status == kRayDone) {
    hits[n] = trace_result();
    atomicAdd(counters.rays[node.kind], 1u);
    nodes[n].status = kRayDone;
  } else if (status == kRayBudget) {
    requeue(n);
  }
}
