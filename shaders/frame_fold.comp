#version 460
// Wavefront, after the last wave, one dispatch per depth from the deepest up: a node's radiance
// is its starting value plus its visible shadow rays in light order, then its refraction child
// and its reflection child × their weights (the CPU's fold: children in reverse creation order).
// The primaries (depth 0, node i = the chunk's pixel i) write the image. Each dispatch covers the
// nodes [pc.first, pc.count) that may have its depth (kWaveMarks), not the whole buffer.
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/frame_wavefront.glsl"

layout(local_size_x = 64) in;

void main() {
  uint n = pc.first + gl_GlobalInvocationID.x;
  if (n >= pc.count) return;
  // Field by field, each where it is needed: a node of another depth reads one word, and only
  // a ray leaving a cube reads what its record carries.
  uint depth = nodes[n].depth;
  if (depth != pc.depth) return;
  vec3 radiance = nodes[n].radiance;
  uint seen = kCache ? nodes[n].seen : 0u, rays = kCache ? nodes[n].rays : 0u;
  uint shadow_count = nodes[n].shadow_count, shadow_first = nodes[n].shadow_first;
  for (uint k = 0u; k < kLightCount; ++k) {
    if (k >= shadow_count) break;
    GpuShadowRay s = shadows[shadow_first + k];
    if (s.status == kRayPending) atomicAdd(counters.cut, 1u);
    else if (s.status == kRayDone && s.visible != 0u) radiance = radiance + s.value;
  }
  uint refract = nodes[n].child_refract, reflect = nodes[n].child_reflect;
  if (refract != kNoIndex) {
    radiance = radiance + vec3(nodes[refract].weight) * nodes[refract].radiance;
    if (kCache) {
      seen |= nodes[refract].seen;
      rays += nodes[refract].rays;
    }
  }
  if (reflect != kNoIndex) {
    radiance = radiance + vec3(nodes[reflect].weight) * nodes[reflect].radiance;
    if (kCache) {
      seen |= nodes[reflect].seen;
      rays += nodes[reflect].rays;
    }
  }
  nodes[n].radiance = radiance;
  if (kCache) {
    nodes[n].seen = seen;
    nodes[n].rays = rays;
    uint leaves = nodes[n].leaves;
    if (leaves != kNoIndex) {
      // What the CPU hands the store: the first hit of a traced ray (none for a served one).
      GpuFrameNode node = nodes[n];
      float hit_t = kInfinity;
      uint entity = kNoIndex;
      if ((node.answer & 15u) != kAnswerUse) {
        GpuHit hit = hits[n];
        if (hit.instance != kNoIndex) {
          hit_t = hit.t;
          entity = instances[hit.instance].entity_index;
        }
      }
      cache_record(leaves, node.origin, node.direction, node.pixel, radiance, hit_t, entity, seen,
                   rays, depth, node.kind, node.answer, node.throughput);
    }
  }
  if (depth == 0u) write_pixel(nodes[n].pixel, radiance);
}
