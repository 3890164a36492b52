#version 460
// Wavefront, after the last wave, one dispatch per depth from the deepest up: a node's radiance
// is its starting value plus its visible shadow rays in light order, then its refraction child
// and its reflection child × their weights (the CPU's fold: children in reverse creation order).
// The primaries (depth 0, node p = pixel p) write the image.
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/frame_wavefront.glsl"

layout(local_size_x = 64) in;

void main() {
  uint n = gl_GlobalInvocationID.x;
  if (n >= pc.count) return;
  GpuFrameNode node = nodes[n];
  if (node.depth != pc.depth) return;
  precise vec3 radiance = node.radiance;
  for (uint k = 0u; k < kLightCount; ++k) {
    if (k >= node.shadow_count) break;
    GpuShadowRay s = shadows[node.shadow_first + k];
    if (s.status == kRayPending) atomicAdd(counters.cut, 1u);
    else if (s.status == kRayDone && s.visible != 0u) radiance = radiance + s.value;
  }
  if (node.child_refract != kNoIndex) {
    GpuFrameNode c = nodes[node.child_refract];
    radiance = radiance + vec3(c.weight) * c.radiance;
  }
  if (node.child_reflect != kNoIndex) {
    GpuFrameNode c = nodes[node.child_reflect];
    radiance = radiance + vec3(c.weight) * c.radiance;
  }
  nodes[n].radiance = radiance;
  if (node.depth == 0u) write_pixel(node.pixel, radiance);
}
