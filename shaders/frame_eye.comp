#version 460
// Wavefront, eye-ray generation: node i is the chunk's pixel i's primary ray, queued for wave 0.
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/frame_wavefront.glsl"

layout(local_size_x = 64) in;

void main() {
  // Node i is the chunk's pixel i (a frame whose trees would outgrow the node buffer is rendered
  // in chunks of pixels, DeviceRenderer::run_wavefront).
  uint i = gl_GlobalInvocationID.x;
  if (i >= params.chunk_pixels) return;
  uint p = params.first_pixel + i;
  GpuFrameNode n;
  n.origin = params.camera_origin;
  n.tfar = kInfinity;
  n.direction = camera_direction(p % params.width, p / params.width);
  n.pixel = p;
  n.throughput = vec3(1.0);
  n.depth = 0u;
  n.radiance = vec3(0.0);
  n.weight = 1.0;
  n.kind = kKindPrimary;
  n.status = kRayPending;
  n.child_reflect = kNoIndex;
  n.child_refract = kNoIndex;
  n.shadow_first = 0u;
  n.shadow_count = 0u;
  n.seen = 0u;
  n.rays = 0u;
  n.leaves = kNoIndex;
  n.answer = kAnswerTrace;
  n.resume = kNoIndex;
  n._pad1 = 0u;
  nodes[i] = n;
  queues[i] = i;
  primary_instance[p] = kNoIndex;
}
