#version 460
// Wavefront hybrid mode, after frame_eye: the chunk's pixel i's primary ray (node i) takes its hit
// from the raster pass (include/visibility.glsl); frame_trace skips the nodes settled here and
// traces the rest.
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/frame_wavefront.glsl"
#include "include/visibility.glsl"

layout(local_size_x = 64) in;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= params.chunk_pixels) return;
  GpuFrameNode node = nodes[i];
  GpuHit hit;
  if (!visibility_hit(params.first_pixel + i, node.origin, node.direction, hit)) return;
  hits[i] = hit;
  atomicAdd(counters.rays[node.kind], 1u);
  nodes[i].status = kRayDone;
}
