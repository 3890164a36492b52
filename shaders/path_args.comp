#version 460
// Path and shadow frames, before a trace pass: the indirect dispatch size of the queue it reads
// (pc.count 0: paths, 1: shadow rays), and the other queue of that kind emptied for the rays the
// pass re-queues, and the state pool it saves into (trace_pool.glsl).
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/path.glsl"

layout(local_size_x = 1) in;

void main() {
  if (pc.count == 0u) {
    uint n = min(counters.queue_count[pc.parity], params.node_capacity);
    counters.ray_args = GpuDispatch((n + 63u) / 64u, 1u, 1u);
    counters.queue_count[1u - pc.parity] = 0u;
  } else {
    uint n = min(counters.shadow_queue_count[pc.parity], params.shadow_capacity);
    counters.shadow_args = GpuDispatch((n + 63u) / 64u, 1u, 1u);
    counters.shadow_queue_count[1u - pc.parity] = 0u;
  }
  counters.state_count[1u - pc.parity] = 0u;
}
