// Ray-cache cubes in the frame kernels (engine/gpu/device_cache.h): the lookup that
// RayCacheStore::lookup makes for a ray leaving a cached object (Direction, Tau and March modes),
// and the record of a traced leaving ray that the store receives after the frame (its leaving()).
// Only compiled in when the frame has cubes (kCache).
#ifndef SPECULA_FRAME_CACHE_GLSL
#define SPECULA_FRAME_CACHE_GLSL

#include "shared/cache_layout.h"
#include "include/cube.glsl"
#include "include/hash.glsl"

layout(constant_id = 5) const bool kCache = false;

layout(std430, set = 0, binding = 20) readonly buffer CacheCubes { GpuCube cubes[]; };
layout(std430, set = 0, binding = 21) readonly buffer CacheTexels { uvec4 texels[]; };
layout(std430, set = 0, binding = 22) writeonly buffer CacheRecords { GpuLeavingRecord records[]; };
layout(std430, set = 0, binding = 31) buffer CacheCounts { uint cube_counts[]; };

// Answer bits beside the CacheAnswer value: the ray was looked up (the host replays the lookup
// where every ray is recorded); above them, the texel the lookup read (kAnswerTexelShift).
const uint kAnswerLookedUp = 16u;

// Adds v to word `field` of slot's counts (kCount*, cache_layout.h): one atomic for the
// subgroup's active lanes where they share the slot (adjacent pixels mostly leave one object).
void cache_count(uint slot, uint field, uint v) {
  uint at = slot * kCubeCountWords + field;
  if (subgroupAllEqual(slot)) {
    uint sum = subgroupAdd(v);
    if (subgroupElect() && sum != 0u) atomicAdd(cube_counts[at], sum);
  } else if (v != 0u) {
    atomicAdd(cube_counts[at], v);
  }
}

// As cache_count, into a 64-bit sum (low word at `field`, high word after it).
void cache_count64(uint slot, uint field, uint v) {
  uint at = slot * kCubeCountWords + field;
  uint sum = v;
  bool add = v != 0u;
  if (subgroupAllEqual(slot)) {
    sum = subgroupAdd(v);
    add = subgroupElect() && sum != 0u;
  }
  if (add) {
    uint before = atomicAdd(cube_counts[at], sum);
    if (before + sum < before) atomicAdd(cube_counts[at + 1u], 1u);
  }
}

// The slot whose cube gets a record of a ray leaving instance `slot` (kNoIndex: none). Only rays
// that go away from the object (exits) are the cube's.
uint cache_leaves(uint slot, bool exits) {
  if (!kCache || !exits) return kNoIndex;
  return cubes[slot].mode != kCubeNone ? slot : kNoIndex;
}

// within_tau (ray_cache.cpp): the cached hit centre + s·distance, seen from p, within τ of d.
bool cache_within_tau(vec3 centre, vec3 s, float distance, vec3 p, vec3 d, float cos_tau) {
  vec3 sd = s * distance;
  vec3 hit = centre + sd;
  vec3 v = hit - p;
  float len = length3(v);
  float bound = cos_tau * len;
  return len > 0.0 && dot3(v, d) >= bound;
}

// cache::verify_chosen (ray_cache.h): whether auto traces this accepted lookup anyway. Whitted
// frames have one sample per pixel (sample 0).
bool cache_verify(GpuCube c, uint pixel, uint depth) {
  uint h = hash_combine(hash_combine(hash_combine(hash_u32(pixel), depth), c.frame), c.index);
  return c.verify_every != 0u && h % c.verify_every == 0u;
}

// ray_cache.cpp's march, operation for operation: where the ray origin + t·direction first goes
// beyond the stored surface (|q − c| ≥ the texel's distance), stepping about a texel of angle (or
// the gap to the surface) at a time, then bisecting; the texel found is used if its stored hit
// lies within τ of the ray. A ray whose direction from the centre converges on its own without
// crossing anything sees what the texel of its direction saw: a miss, confirmed by an occlusion
// ray (kAnswerUseIfClear). Returns kAnswerTrace (outdated, rejected, out of steps), kAnswerUse or
// kAnswerUseIfClear, with the texel's index in `texel`. At most kCubeMarchIterations iterations.
uint cache_march(GpuCube c, vec3 p, vec3 d, out uint texel, out bool outdated, out uint steps) {
  texel = 0u;
  outdated = false;
  steps = 0u;
  uint res = c.resolution;
  vec3 pc = p - c.centre;
  float texel_angle = 2.0 / float(res);
  float scale = max(length3(pc), 1e-6);
  float least = 1e-4 * scale;
  float t = 0.0;
  float t_inside = 0.0;
  for (uint step = 0u; step < kCubeMarchSteps; ++step) {
    ++steps;
    vec3 q = pc + t * d;
    float r = length3(q);
    uint ti = cube_texel(r > 0.0 ? q : d, res);
    uvec4 tx = texels[c.first_texel + ti];
    if (!texel_valid(tx)) {
      outdated = true;
      return kAnswerTrace;
    }
    float D = texel_distance(tx);
    if (isinf(D)) {
      float bound = r * c.cos_half_texel;
      if (r > 0.0 && dot3(q, d) >= bound) {
        uint td = cube_texel(d, res);
        uvec4 own = texels[c.first_texel + td];
        outdated = !texel_valid(own);
        if (outdated || !isinf(texel_distance(own))) return kAnswerTrace;
        texel = td;
        return kAnswerUseIfClear;
      }
    } else if (r >= D) {
      // Crossed between t_inside and t: bisect.
      float lo = t_inside, hi = t;
      uint found = ti;
      for (uint k = 0u; k < kCubeRefineSteps; ++k) {
        ++steps;
        float mid = 0.5 * (lo + hi);
        vec3 qm = pc + mid * d;
        float rm = length3(qm);
        uint tm = cube_texel(rm > 0.0 ? qm : d, res);
        uvec4 mx = texels[c.first_texel + tm];
        if (!texel_valid(mx)) {
          outdated = true;
          return kAnswerTrace;
        }
        float Dm = texel_distance(mx);
        if (!isinf(Dm) && rm >= Dm) {
          hi = mid;
          found = tm;
        } else {
          lo = mid;
        }
      }
      vec3 q_hit = pc + hi * d;
      float r_hit = length3(q_hit);
      vec3 s = r_hit > 0.0 ? q_hit / r_hit : d;
      if (!cache_within_tau(c.centre, s, texel_distance(texels[c.first_texel + found]), p, d,
                            c.cos_tau))
        return kAnswerTrace;
      texel = found;
      return kAnswerUse;
    }
    t_inside = t;
    // About one texel of angle as seen from the centre, never past the surface when the stored
    // distance does not change.
    float perp = r > 0.0 ? length3(cross3(d, q)) / r : 0.0;
    float dt = perp > 1e-12 ? texel_angle * r * r / perp : kInfinity;
    if (!isinf(D)) {
      float gap = max(D - r, 0.0) + least;
      dt = min(dt, gap);
    }
    float next = t + max(dt, least);
    t = next;
    if (isinf(t) || isnan(t)) break;
  }
  return kAnswerTrace; // ran out of steps: trace
}

// RayCacheStore::lookup for one ray leaving `slot` (a cube's) from `pixel` at `depth`:
// kAnswerTrace, or kAnswerUse / kAnswerUseIfClear with the texel's radiance and seen mask, or
// kAnswerVerify (traced as kAnswerTrace, its radiance and mask left 0), | kAnswerLookedUp when
// the cube is looked up at all this frame, | the texel read << kAnswerTexelShift. Counts the
// lookup in the slot's counts as the store's lookup() counts it.
uint cache_lookup(uint slot, uint pixel, uint depth, vec3 origin, vec3 direction,
                  out vec3 radiance, out uint seen) {
  radiance = vec3(0.0);
  seen = 0u;
  GpuCube c = cubes[slot];
  if ((c.flags & kCubeEnabled) == 0u) return kAnswerTrace;
  uint texel = cube_texel(direction, c.resolution);
  uint answer = kAnswerTrace;
  bool outdated = false;
  uint steps = 0u;
  if (c.mode == kCubeMarch) {
    answer = cache_march(c, origin, direction, texel, outdated, steps);
  }
  uvec4 t = texels[c.first_texel + texel];
  if (c.mode != kCubeMarch) {
    outdated = !texel_valid(t);
    if (!outdated) {
      if (c.mode == kCubeDirection) {
        answer = kAnswerUse;
      } else {
        float d = texel_distance(t);
        if (isinf(d)) answer = kAnswerUseIfClear; // a miss: an occlusion ray confirms
        else if (cache_within_tau(c.centre, direction, d, origin, direction, c.cos_tau))
          answer = kAnswerUse;
      }
    }
  }
  bool verify = answer != kAnswerTrace && cache_verify(c, pixel, depth);
  cache_count(slot, kCountLookups, 1u);
  cache_count(slot, kCountOutdated, outdated ? 1u : 0u);
  cache_count(slot, kCountRejected, answer == kAnswerTrace && !outdated ? 1u : 0u);
  if (c.mode == kCubeMarch) cache_count64(slot, kCountSteps, steps);
  // What a served texel cost when it was traced (the store's offered rays).
  cache_count64(slot, kCountOffered, answer != kAnswerTrace && !verify ? (t.w >> 16) & 0xFFu : 0u);
  uint bits = kAnswerLookedUp | (texel << kAnswerTexelShift);
  if (verify) return kAnswerVerify | bits;
  if (answer != kAnswerTrace) {
    radiance = texel_radiance(t);
    uint hit = texel_hit(t);
    seen = texel_seen(t) | (hit != kNoIndex ? 1u << (hit & 31u) : 0u);
  }
  return answer | bits;
}

// A ray leaving a cube's object once its subtree is folded. Recorded for the host (the store's
// leaving()) where every ray is (kCubeRecordAll) or where it may change the store: traced with
// its texel outdated (a write) or verified (an error sample); otherwise counted here. Records
// past the buffer are counted (the host reports the overflow).
void cache_record(uint slot, vec3 origin, vec3 direction, uint pixel, vec3 radiance, float hit_t,
                  uint hit_entity, uint seen, uint rays, uint depth, uint kind, uint answer,
                  vec3 throughput) {
  GpuCube c = cubes[slot];
  uint a = answer & 15u;
  if ((c.flags & kCubeRecordAll) == 0u) {
    // The store writes only outdated texels: a traced ray finding its texel valid changes
    // nothing but the counts.
    bool served = a == kAnswerUse || a == kAnswerUseIfClear;
    bool counted = served || (a == kAnswerTrace &&
                              texel_valid(texels[c.first_texel + cube_texel(direction, c.resolution)]));
    // Each word in a call of its own: the subgroup sums one word at a time.
    cache_count(slot, kCountUsed, served ? 1u : 0u);
    cache_count64(slot, kCountUsedRays, served ? rays : 0u);
    cache_count(slot, kCountTraced, counted && !served ? 1u : 0u);
    cache_count64(slot, kCountTracedRays, counted && !served ? rays : 0u);
    if (counted) return;
  }
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
  r.packed = depth | (kind << 8) | ((answer & 31u) << 12);
  r.throughput = throughput;
  r.texel = answer >> kAnswerTexelShift;
  records[k] = r;
}

#endif
