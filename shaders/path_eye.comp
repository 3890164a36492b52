#version 460
// Path and shadow frames: each path of the chunk starts at its pixel's camera ray (the CPU's
// primary rays: pixel centres, shared by the pixel's samples), queued for the first trace pass.
// Only a pixel's first sample of the frame counts its primary ray, as the CPU traces it once.
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/path.glsl"

layout(local_size_x = 64) in;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= pp.path_count) return;
  uint pixel = pp.first_pixel + i / pp.batch;
  uint s = i % pp.batch;
  GpuPath p;
  p.origin = params.camera_origin;
  p.tfar = kInfinity;
  p.direction = camera_direction(pixel % params.width, pixel / params.width);
  p.pixel = pixel;
  p.throughput = vec3(1.0);
  p.sample_index = pp.sample_offset + pp.first_sample + s;
  p.radiance = vec3(0.0);
  p.bsdf_pdf = 0.0;
  p.previous = vec3(0.0);
  p.status = kRayPending;
  p.depth = 0u;
  p.kind = pp.first_sample == 0u && s == 0u ? kKindPrimary : kKindUncounted;
  p.alive = 1u;
  p.shadow_count = 0u;
  paths[i] = p;
  queues[i] = i;
}
