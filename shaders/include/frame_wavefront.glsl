// The wavefront's own buffers: the rays of every pixel's Whitted tree (nodes, appended as they are
// spawned), their hits, two ray queues used in turn by successive waves, the shadow rays and
// their two queues.
#ifndef SPECULA_FRAME_WAVEFRONT_GLSL
#define SPECULA_FRAME_WAVEFRONT_GLSL

#include "include/frame_common.glsl"

layout(std430, set = 0, binding = 15) buffer FrameNodes { GpuFrameNode nodes[]; };
layout(std430, set = 0, binding = 16) buffer FrameHits { GpuHit hits[]; };
layout(std430, set = 0, binding = 17) buffer FrameQueues { uint queues[]; };
layout(std430, set = 0, binding = 18) buffer FrameShadows { GpuShadowRay shadows[]; };
layout(std430, set = 0, binding = 19) buffer FrameShadowQueues { uint shadow_queues[]; };

// Which queue a wave reads (the other is the one it appends to); the wave's index (frame_args)
// or the fold's depth, and the fold's node range [first, count).
layout(push_constant) uniform WavePush { uint parity; uint depth; uint count; uint first; } pc;

void push_ray(uint node) {
  uint slot = atomicAdd(counters.queue_count[1u - pc.parity], 1u);
  if (slot < params.node_capacity) queues[(1u - pc.parity) * params.node_capacity + slot] = node;
}
void push_shadow(uint s) {
  uint slot = atomicAdd(counters.shadow_queue_count[1u - pc.parity], 1u);
  if (slot < params.shadow_capacity)
    shadow_queues[(1u - pc.parity) * params.shadow_capacity + slot] = s;
}

#endif
