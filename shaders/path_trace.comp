#version 460
// Path and shadow frames, traversal + intersection of the queued paths' rays. A ray that uses up
// this dispatch's budget keeps its closest hit so far and is queued for the next pass, which
// resumes it (trace_closest_resume: the same hit as one uninterrupted trace).
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/path.glsl"

layout(local_size_x = 64) in;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= min(counters.queue_count[pc.parity], params.node_capacity)) return;
  uint n = queues[pc.parity * params.node_capacity + i];
  bool resumed = paths[n].status == kRayBudget;
  // Pending until one of the exits below: a ray still pending afterwards was cut by the driver.
  paths[n].status = kRayPending;
  GpuPath p = paths[n];
  uint budget = params.budget;
  GpuHit hit;
  hit.instance = kNoIndex;
  uint status;
  if (resumed) {
    hit = hits[n];
    status = trace_closest_resume(p.origin, p.direction, 0.0, p.tfar, budget, hit);
  } else {
    status = trace_closest(p.origin, p.direction, 0.0, p.tfar, budget, hit);
  }
  if (status == kRayDone) {
    hits[n] = hit;
    if (p.kind < kKindUncounted) atomicAdd(counters.rays[p.kind], 1u);
    paths[n].status = kRayDone;
  } else if (status == kRayBudget) {
    hits[n] = hit;
    atomicAdd(counters.resumed, 1u);
    paths[n].status = kRayBudget;
    push_path(1u - pc.parity, n);
  }
}
