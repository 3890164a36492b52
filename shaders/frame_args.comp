#version 460
// Wavefront: before a wave, the indirect dispatch sizes of its ray and shadow queues (the ones
// the previous wave appended to), and the queues and the state pool it appends to emptied; the
// node count before the wave's shading marked (wave pc.depth) for the fold's ranges.
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/frame_wavefront.glsl"

layout(local_size_x = 1) in;

void main() {
  uint rays = min(counters.queue_count[pc.parity], params.node_capacity);
  uint shadow_rays = min(counters.shadow_queue_count[pc.parity], params.shadow_capacity);
  counters.ray_args.x = (rays + 63u) / 64u;
  counters.ray_args.y = 1u;
  counters.ray_args.z = 1u;
  counters.shadow_args.x = (shadow_rays + 63u) / 64u;
  counters.shadow_args.y = 1u;
  counters.shadow_args.z = 1u;
  counters.queue_count[1u - pc.parity] = 0u;
  counters.shadow_queue_count[1u - pc.parity] = 0u;
  counters.state_count[1u - pc.parity] = 0u;
  if (pc.depth < kWaveMarks)
    counters.wave_nodes[pc.depth] = min(counters.node_count, params.node_capacity);
}
