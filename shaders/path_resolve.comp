#version 460
// Path and shadow frames, after a batch: each pixel of the chunk adds its batch's samples in
// sample order (a non-finite one counted and taken as 0, the CPU's finite_or_counted) to its sum;
// after the last batch the image gets the mean.
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/path.glsl"

layout(local_size_x = 64) in;

void main() {
  uint j = gl_GlobalInvocationID.x;
  if (j * pp.batch >= pp.path_count) return;
  uint pixel = pp.first_pixel + j;
  vec3 sum = pp.first_sample == 0u ? vec3(0.0) : sums[pixel].xyz;
  for (uint s = 0u; s < pp.batch; ++s) {
    vec3 r = paths[j * pp.batch + s].radiance;
    if (finite3(r)) sum = sum + r;
    else atomicAdd(counters.nonfinite, 1u);
  }
  if (pp.last_batch == 0u) {
    sums[pixel] = vec4(sum, 0.0);
    return;
  }
  vec3 mean = sum * (1.0 / float(pp.spp));
  image[pixel] = vec4(pp.spp == 1u ? sum : mean, 1.0);
}
