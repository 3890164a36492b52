#version 460
// Path and shadow frames, single kernel: one invocation per path walks it to its end in a bounded
// loop, each step one trace: the path's ray (then its vertex is shaded at once, the same
// include/path_shade.glsl as the wavefront's), or the next of the shadow rays that shading wrote
// to the path's slots, in slot order; once they are all traced their visible values are added
// (gather_shadows) and the path's next ray goes. The walk's whole state is in buffers: the path
// record, its shadow slots, the cursor of the next slot to trace (queues[i], which the wavefront
// uses for its queues) and, for a trace that used up the dispatch's budget, its saved walk in the
// path's own pool slot i (trace_pool.glsl). So a walk stopped by the budget, or by the step
// bound, goes on in the next dispatch exactly where it stopped, and the image is the wavefront's
// (and the CPU's) bit for bit.
#extension GL_GOOGLE_include_directive : require
#define SPECULA_PATH_SINGLE
#include "include/common.glsl"
#include "include/path_gather.glsl"
#include "include/path_shade.glsl"

layout(local_size_x = 64) in;

// Traces per dispatch, besides the traversal budget (lavapipe ends loops silently: see
// device_path.h).
const uint kMaxSteps = 256u;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= pp.path_count) return;
  uint budget = params.budget;
  bool stopped = false; // by the budget; the path's end returns
  uint step = 0u;
  for (; step < kMaxSteps; ++step) {
    uint count = paths[i].shadow_count;
    if (count > 0u) {
      uint k = queues[i];
      if (k >= count) { // every shadow ray of this vertex traced
        gather_shadows(i);
        queues[i] = 0u;
        continue;
      }
      uint s = i * pp.shadow_slots + k;
      GpuShadowRay ray = shadows[s];
      if (ray.status != kRayDone) {
        uint slot = ray.status == kRayBudget ? i : kNoIndex;
        shadows[s].status = kRayPending; // until one of the exits below
        uint status = pool_trace(slot, ray.origin, ray.direction, 0.0, ray.tfar, true, budget);
        if (status == kRayBudget) {
          pool_store(i);
          shadows[s].status = kRayBudget;
          stopped = true;
          break;
        }
        if (status != kRayDone) break; // cut by the driver
        atomicAdd(counters.rays[kKindShadow], 1u);
        shadows[s].visible = tr_occluded ? 0u : 1u;
        shadows[s].status = kRayDone;
      }
      queues[i] = k + 1u;
      continue;
    }
    if (paths[i].alive == 0u) return; // ended, its shadow rays gathered
    GpuPath p = paths[i];
    uint slot = p.status == kRayBudget ? i : kNoIndex;
    paths[i].status = kRayPending;
    uint status = pool_trace(slot, p.origin, p.direction, 0.0, p.tfar, false, budget);
    if (status == kRayBudget) {
      pool_store(i);
      paths[i].status = kRayBudget;
      stopped = true;
      break;
    }
    if (status != kRayDone) break;
    hits[i] = trace_result();
    if (p.kind < kKindUncounted) atomicAdd(counters.rays[p.kind], 1u);
    p.status = kRayDone;
    paths[i].status = kRayDone;
    shade_path(i, p);
  }
  // Out of budget or steps: resumed by the next dispatch. Leaving the loop any other way means
  // the driver ended it (the path still resumes where its records say, a cut trace from its start).
  if (!stopped && step < kMaxSteps) atomicAdd(counters.cut, 1u);
  atomicAdd(counters.pending, 1u);
  atomicAdd(counters.resumed, 1u);
}
