#version 460
// Path and shadow frames, traversal + intersection of the queued paths' rays. A ray that uses up
// this dispatch's budget saves its walk (trace_pool.glsl; the slot kept in hits[n].primitive
// meanwhile) and is queued for the next pass, which goes on from there.
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/path.glsl"

layout(local_size_x = 64) in;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= min(counters.queue_count[pc.parity], params.node_capacity)) return;
  uint n = queues[pc.parity * params.node_capacity + i];
  uint slot = paths[n].status == kRayBudget ? hits[n].primitive : kNoIndex;
  // Pending until one of the exits below: a ray still pending afterwards was cut by the driver.
  paths[n].status = kRayPending;
  GpuPath p = paths[n];
  uint budget = params.budget;
  uint status = pool_trace(slot, p.origin, p.direction, 0.0, p.tfar, false, budget);
  if (status == kRayDone) {
    hits[n] = trace_result();
    if (p.kind < kKindUncounted) atomicAdd(counters.rays[p.kind], 1u);
    paths[n].status = kRayDone;
  } else if (status == kRayBudget) {
    hits[n].primitive = pool_save(1u - pc.parity);
    atomicAdd(counters.resumed, 1u);
    paths[n].status = kRayBudget;
    push_path(1u - pc.parity, n);
  }
}
