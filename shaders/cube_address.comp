#version 460
// Test kernel: the face and texel that cube.glsl addresses for each direction
// (tests/gpu/test_device_cache.cpp compares them with cube_map.h).
#extension GL_GOOGLE_include_directive : require
#include "include/cube.glsl"

layout(local_size_x = 64) in;
layout(std430, set = 0, binding = 0) readonly buffer Directions { vec4 directions[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Addresses { uvec2 addresses[]; };
layout(push_constant) uniform Push { uint count; uint resolution; } pc;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= pc.count) return;
  vec3 s = directions[i].xyz;
  float u, v;
  addresses[i] = uvec2(cube_coord(s, u, v), cube_texel(s, pc.resolution));
}
