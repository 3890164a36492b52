// Ray-cache cubes in the frame kernels (engine/gpu/device_cache.h): the lookup that
// RayCacheStore::lookup makes for a ray leaving a cached object (Direction and Tau modes), and the
// record of a traced leaving ray that the store receives after the frame (its leaving()). Only
// compiled in when the frame has cubes (kCache).
#ifndef SPECULA_FRAME_CACHE_GLSL
#define SPECULA_FRAME_CACHE_GLSL

#include "shared/cache_layout.h"
#include "include/cube.glsl"
#include "include/hash.glsl"

layout(constant_id = 5) const bool kCache = false;

layout(std430, set = 0, binding = 20) readonly buffer CacheCubes { GpuCube cubes[]; };
layout(std430, set = 0, binding = 21) readonly buffer CacheTexels { uvec4 texels[]; };
layout(std430, set = 0, binding = 22) writeonly buffer CacheRecords { GpuLeavingRecord records[]; };

// Answer bits beside the CacheAnswer value: the ray was looked up (the host replays the lookup).
const uint kAnswerLookedUp = 16u;

// The slot whose cube gets a record of a ray leaving instance `slot` (kNoIndex: none). Only rays
// that go away from the object (exits) are the cube's.
uint cache_leaves(uint slot, bool exits) {
  if (!kCache || !exits) return kNoIndex;
  return cubes[slot].mode != kCubeNone ? slot : kNoIndex;
}

// within_tau (ray_cache.cpp): the cached hit centre + s·distance, seen from p, within τ of d.
bool cache_within_tau(vec3 centre, vec3 s, float distance, vec3 p, vec3 d, float cos_tau) {
  precise vec3 sd = s * distance;
  precise vec3 hit = centre + sd;
  precise vec3 v = hit - p;
  float len = length3(v);
  precise float bound = cos_tau * len;
  return len > 0.0 && dot3(v, d) >= bound;
}

// cache::verify_chosen (ray_cache.h): whether auto traces this accepted lookup anyway. Whitted
// frames have one sample per pixel (sample 0).
bool cache_verify(GpuCube c, uint pixel, uint depth) {
  uint h = hash_combine(hash_combine(hash_combine(hash_u32(pixel), depth), c.frame), c.index);
  return c.verify_every != 0u && h % c.verify_every == 0u;
}

// RayCacheStore::lookup for one ray leaving `slot` (a cube's) from `pixel` at `depth`:
// kAnswerTrace, or kAnswerUse / kAnswerUseIfClear with the texel's radiance and seen mask, or
// kAnswerVerify (traced as kAnswerTrace, its radiance and mask left 0: the host takes the cached
// value from the store), | kAnswerLookedUp when the cube is looked up at all this frame.
uint cache_lookup(uint slot, uint pixel, uint depth, vec3 origin, vec3 direction,
                  out vec3 radiance, out uint seen) {
  radiance = vec3(0.0);
  seen = 0u;
  GpuCube c = cubes[slot];
  if ((c.flags & kCubeEnabled) == 0u) return kAnswerTrace;
  uvec4 t = texels[c.first_texel + cube_texel(direction, c.resolution)];
  uint answer = kAnswerTrace;
  if (texel_valid(t)) {
    if (c.mode == kCubeDirection) {
      answer = kAnswerUse;
    } else {
      float d = texel_distance(t);
      if (isinf(d)) answer = kAnswerUseIfClear; // a miss: an occlusion ray confirms
      else if (cache_within_tau(c.centre, direction, d, origin, direction, c.cos_tau))
        answer = kAnswerUse;
    }
  }
  if (answer != kAnswerTrace && cache_verify(c, pixel, depth))
    return kAnswerVerify | kAnswerLookedUp;
  if (answer != kAnswerTrace) {
    radiance = texel_radiance(t);
    uint hit = texel_hit(t);
    seen = texel_seen(t) | (hit != kNoIndex ? 1u << (hit & 31u) : 0u);
  }
  return answer | kAnswerLookedUp;
}

// The record of a ray leaving a cube's object once its subtree is folded; records past the
// buffer are counted (the host reports the overflow).
void cache_record(uint slot, vec3 origin, vec3 direction, uint pixel, vec3 radiance, float hit_t,
                  uint hit_entity, uint seen, uint rays, uint depth, uint kind, uint answer,
                  vec3 throughput) {
  uint k = atomicAdd(counters.records, 1u);
  if (k >= params.record_capacity) return;
  GpuLeavingRecord r;
  r.origin = origin;
  r.instance = slot;
  r.direction = direction;
  r.pixel = pixel;
  r.radiance = radiance;
  r.hit_t = hit_t;
  r.hit_entity = hit_entity;
  r.seen = seen;
  r.rays = rays;
  r.packed = depth | (kind << 8) | (answer << 12);
  r.throughput = throughput;
  r._pad0 = 0u;
  records[k] = r;
}

#endif
