#version 460
// Wavefront, traversal + intersection of a wave's rays. A ray that uses up this dispatch's
// traversal budget is queued for the next wave, which traces it again (trace.glsl's contract:
// kRayBudget means "call again in a later dispatch").
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/frame_wavefront.glsl"

layout(local_size_x = 64) in;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= min(counters.queue_count[pc.parity], params.node_capacity)) return;
  uint n = queues[pc.parity * params.node_capacity + i];
  // Hybrid mode: frame_visibility.comp already found this primary ray's hit.
  if (nodes[n].status == kRayDone) return;
  // Pending until one of the exits below: a ray still pending afterwards was cut by the driver.
  nodes[n].status = kRayPending;
  GpuFrameNode node = nodes[n];
  uint budget = params.budget;
  if (kCache && (node.answer & 15u) == kAnswerUseIfClear) {
    // A cached miss (Tau mode): the CPU's occlusion ray confirms nothing lies on the way; if
    // something does, the ray is traced after all (two rays for it, its radiance its own).
    bool occluded = false;
    uint confirm = trace_any(node.origin, node.direction, 0.0, kInfinity, budget, occluded);
    if (confirm == kRayBudget) {
      atomicAdd(counters.resumed, 1u);
      nodes[n].status = kRayBudget;
      push_ray(n);
      return;
    }
    if (confirm != kRayDone) return; // cut by the driver: left pending
    atomicAdd(counters.rays[kKindShadow], 1u);
    if (!occluded) {
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
  GpuHit hit;
  hit.instance = kNoIndex;
  uint status = trace_closest(node.origin, node.direction, 0.0, node.tfar, budget, hit);
  if (status == kRayDone) {
    hits[n] = hit;
    atomicAdd(counters.rays[node.kind], 1u);
    nodes[n].status = kRayDone;
  } else if (status == kRayBudget) {
    atomicAdd(counters.resumed, 1u);
    nodes[n].status = kRayBudget;
    push_ray(n);
  }
}
