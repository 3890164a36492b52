#version 460
// Test kernel (test_device_path): sampler.glsl's points for (pixel, seed, index, set) queries,
// 4 dimensions each as 32-bit fractions, to compare with sampler.h bit for bit.
#extension GL_GOOGLE_include_directive : require

layout(local_size_x = 64) in;
layout(std430, set = 0, binding = 0) readonly buffer Tables { uint sobol_tables[]; };
layout(std430, set = 0, binding = 1) readonly buffer Queries { uvec4 queries[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Points { uvec4 points[]; };
layout(push_constant) uniform Push { uint count; } pc;

#include "include/sampler.glsl"

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= pc.count) return;
  uvec4 q = queries[i]; // pixel, seed, index, set
  uvec2 s = sample_set(pixel_seed(q.x, q.y), q.z, q.w);
  points[i] = uvec4(sample_bits(s, 0u), sample_bits(s, 1u), sample_bits(s, 2u), sample_bits(s, 3u));
}
