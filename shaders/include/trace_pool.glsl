// Saved traversal states for the frame kernels: a ray that uses up a dispatch's budget keeps its
// whole walk (trace.glsl's `tr` and the used part of tr_stack, as trace_rays.comp saves them) in a
// pool slot and goes on from there in a later wave or dispatch, so that no ray needs to finish
// within one dispatch's budget. Wavefront kernels use two pools of params.pool_slots slots by wave
// (or pass) parity: a wave resumes from the pool of its parity and saves into the other one, which
// frame_args / path_args emptied before it. The single kernel has one slot per chunk pixel (one
// trace in flight per walk). A full pool is counted (counters.restarted) and its ray starts over.
#ifndef SPECULA_TRACE_POOL_GLSL
#define SPECULA_TRACE_POOL_GLSL

layout(std430, set = 0, binding = 28) buffer PoolStates { GpuTraceState pool_states[]; };
layout(std430, set = 0, binding = 29) buffer PoolStacks { uvec2 pool_stacks[]; };

// Starts a walk over (tnear, tfar), or, slot != kNoIndex, goes on with the one saved in `slot`
// (same ray); then runs it on `budget` (trace_run's statuses; trace_result / tr_occluded after).
uint pool_trace(uint slot, vec3 org, vec3 dir, float tnear, float tfar, bool any_hit,
                inout uint budget) {
  if (slot == kNoIndex) {
    trace_begin(org, dir, tnear, tfar, any_hit);
  } else {
    tr = pool_states[slot];
    uint base = slot * params.stack_stride;
    for (uint k = 0u; k < tr.sp; ++k) tr_stack[k] = pool_stacks[base + k];
    trace_resume(org, dir, tnear, any_hit);
  }
  return trace_run(budget);
}

// After trace_run returned kRayBudget: the walk into `slot`.
void pool_store(uint slot) {
  tr.tfar = tr_world.tfar;
  pool_states[slot] = tr;
  uint base = slot * params.stack_stride;
  for (uint k = 0u; k < tr.sp; ++k) pool_stacks[base + k] = tr_stack[k];
}

// After trace_run returned kRayBudget: the walk into a free slot of pool `pool` (0 or 1), whose
// index is returned; kNoIndex when the pool is full (the ray will start over).
uint pool_save(uint pool) {
  uint k = atomicAdd(counters.state_count[pool], 1u);
  if (k >= params.pool_slots) {
    atomicAdd(counters.restarted, 1u);
    return kNoIndex;
  }
  uint slot = pool * params.pool_slots + k;
  pool_store(slot);
  return slot;
}

#endif
