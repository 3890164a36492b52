#version 460
// Path and shadow frames, wavefront: shading of one depth's traced paths (include/path_shade.glsl),
// the continuations queued for the next depth's trace passes.
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/path_shade.glsl"

layout(local_size_x = 64) in;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= pp.path_count) return;
  GpuPath p = paths[i];
  if (p.alive == 0u || p.depth != pc.depth) return;
  if (p.status != kRayDone) { // the driver cut its trace
    atomicAdd(counters.cut, 1u);
    end_path(i, p.radiance, 0u);
    return;
  }
  shade_path(i, p);
}
