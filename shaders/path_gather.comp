#version 460
// Path and shadow frames, after a depth's shadow rays are traced: each path adds the values of its
// visible shadow rays in the order its shading wrote them (the CPU's trace_shadows).
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/path.glsl"

layout(local_size_x = 64) in;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= pp.path_count) return;
  uint count = paths[i].shadow_count;
  if (count == 0u) return;
  precise vec3 radiance = paths[i].radiance;
  for (uint k = 0u; k < count; ++k) {
    GpuShadowRay s = shadows[i * pp.shadow_slots + k];
    if (s.status == kRayPending) atomicAdd(counters.cut, 1u);
    else if (s.status == kRayDone && s.visible != 0u) radiance = radiance + s.value;
  }
  paths[i].radiance = radiance;
  paths[i].shadow_count = 0u;
}
