#version 460
// Wavefront hybrid mode, after frame_eye: pixel p's primary ray (node p) takes its hit from the
// raster pass (include/visibility.glsl); frame_trace skips the nodes settled here and traces the
// rest.
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/frame_wavefront.glsl"
#include "include/visibility.glsl"

layout(local_size_x = 64) in;

void main() {
  uint p = gl_GlobalInvocationID.x;
  if (p >= params.pixel_count) return;
  GpuFrameNode node = nodes[p];
  GpuHit hit;
  if (!visibility_hit(p, node.origin, node.direction, hit)) return;
  hits[p] = hit;
  atomicAdd(counters.rays[node.kind], 1u);
  nodes[p].status = kRayDone;
}
