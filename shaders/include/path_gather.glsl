// After a path vertex's shadow rays are traced (path_gather.comp, path_single.comp).
#ifndef SPECULA_PATH_GATHER_GLSL
#define SPECULA_PATH_GATHER_GLSL

#include "include/path.glsl"

// After path i's shadow rays are traced: the values of its visible ones added in the order its
// shading wrote them (the CPU's trace_shadows); a ray left pending was cut by the driver.
void gather_shadows(uint i) {
  uint count = paths[i].shadow_count;
  if (count == 0u) return;
  vec3 radiance = paths[i].radiance;
  for (uint k = 0u; k < count; ++k) {
    GpuShadowRay s = shadows[i * pp.shadow_slots + k];
    if (s.status == kRayPending) atomicAdd(counters.cut, 1u);
    else if (s.status == kRayDone && s.visible != 0u) radiance = radiance + s.value;
  }
  paths[i].radiance = radiance;
  paths[i].shadow_count = 0u;
}

#endif
