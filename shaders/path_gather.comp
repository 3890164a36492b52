#version 460
// Path and shadow frames, wavefront, after a depth's shadow rays are traced: each path adds the
// values of its visible shadow rays in the order its shading wrote them (path.glsl's
// gather_shadows).
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/path_gather.glsl"

layout(local_size_x = 64) in;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= pp.path_count) return;
  gather_shadows(i);
}
