#version 460
// Wavefront, after the last wave, one dispatch per depth from the deepest up: a node's radiance
// is its starting value plus its visible shadow rays in light order, then its refraction child
// and its reflection child × their weights (the CPU's fold: children in reverse creation order).
// The primaries (depth 0, node p = pixel p) write the image. Each dispatch covers the nodes
// [pc.first, pc.count) that may have its depth (kWaveMarks), not the whole buffer.
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/frame_wavefront.glsl"

layout(local_size_x = 64) in;

void main() {
  uint n = pc.first + gl_GlobalInvocationID.x;
  if (n >= pc.count) return;
  GpuFrameNode node = nodes[n];
  if (node.depth != pc.depth) return;
  vec3 radiance = node.radiance;
  uint seen = node.seen, rays = node.rays;
  for (uint k = 0u; k < kLightCount; ++k) {
    if (k >= node.shadow_count) break;
    GpuShadowRay s = shadows[node.shadow_first + k];
    if (s.status == kRayPending) atomicAdd(counters.cut, 1u);
    else if (s.status == kRayDone && s.visible != 0u) radiance = radiance + s.value;
  }
  if (node.child_refract != kNoIndex) {
    GpuFrameNode c = nodes[node.child_refract];
    radiance = radiance + vec3(c.weight) * c.radiance;
    seen |= c.seen;
    rays += c.rays;
  }
  if (node.child_reflect != kNoIndex) {
    GpuFrameNode c = nodes[node.child_reflect];
    radiance = radiance + vec3(c.weight) * c.radiance;
    seen |= c.seen;
    rays += c.rays;
  }
  nodes[n].radiance = radiance;
  if (kCache) {
    nodes[n].seen = seen;
    nodes[n].rays = rays;
    if (node.leaves != kNoIndex) {
      // What the CPU hands the store: the first hit of a traced ray (none for a served one).
      float hit_t = kInfinity;
      uint entity = kNoIndex;
      if ((node.answer & 15u) != kAnswerUse) {
        GpuHit hit = hits[n];
        if (hit.instance != kNoIndex) {
          hit_t = hit.t;
          entity = instances[hit.instance].entity_index;
        }
      }
      cache_record(node.leaves, node.origin, node.direction, node.pixel, radiance, hit_t, entity,
                   seen, rays, node.depth, node.kind, node.answer, node.throughput);
    }
  }
  if (node.depth == 0u) write_pixel(node.pixel, radiance);
}
