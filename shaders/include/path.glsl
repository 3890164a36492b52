// What every path and shadow frame kernel shares (engine/gpu/device_path.h): the frame kernels'
// scene, tables and counters (frame_common.glsl), the path records and their queues, the
// emitter table, the sampler, and the scene features as specialisation constants (ids 7-10 beside
// frame_common's 0-6 and 11-12), so that a scene pays only for what it has.
#ifndef SPECULA_PATH_GLSL
#define SPECULA_PATH_GLSL

#include "include/frame_common.glsl"
#include "shared/path_layout.h"

layout(constant_id = 7) const bool kAreaLights = false; // the emitter table is not empty
layout(constant_id = 8) const bool kMirrors = false;    // some material reflects
layout(constant_id = 9) const bool kShadowMode = false; // shadow caster instead of path tracer
layout(constant_id = 10) const uint kSampling = 0u;      // kSampling{Mis,Bsdf,Light}
layout(constant_id = 13) const bool kGuides = false;    // the frame writes the denoiser's guides

layout(std430, set = 0, binding = 15) buffer Paths { GpuPath paths[]; };
layout(std430, set = 0, binding = 16) buffer PathHits { GpuHit hits[]; };
// Two path queues (params.node_capacity each), used in turn by successive trace passes.
layout(std430, set = 0, binding = 17) buffer PathQueues { uint queues[]; };
layout(std430, set = 0, binding = 18) buffer PathShadows { GpuShadowRay shadows[]; };
layout(std430, set = 0, binding = 19) buffer PathShadowQueues { uint shadow_queues[]; };
layout(std430, set = 0, binding = 23) readonly buffer PathParamsBuffer { GpuPathParams pp; };
layout(std430, set = 0, binding = 24) readonly buffer PathEmitters { GpuEmitter emitters[]; };
layout(std430, set = 0, binding = 25) readonly buffer PathEmitterFirst { uint emitter_first[]; };
layout(std430, set = 0, binding = 26) buffer PathSums { vec4 sums[]; };
layout(std430, set = 0, binding = 27) readonly buffer PathSobol { uint sobol_tables[]; };
layout(std430, set = 0, binding = 30) writeonly buffer PathGuides { GpuGuide guides[]; };

// parity: the queue a pass reads; depth: the vertex depth shaded; count: path_args' queue (0:
// rays, 1: shadow rays); unused: frame_wavefront.glsl's WavePush is as long (frame_shadow serves
// both).
layout(push_constant) uniform PathPush { uint parity; uint depth; uint count; uint unused; } pc;

#include "include/sampler.glsl"

const float kPi = 3.14159265358979323846;

// ---- area_lights.h -------------------------------------------------------------------------------

struct AreaLightSample {
  vec3 position;
  vec3 emission;
  vec3 to_light;
  float distance;
  float pdf;
};

// EmitterTable::pick: the first triangle whose cdf exceeds u (upper_bound), else the last with a
// non-zero probability.
uint pick_emitter(float u) {
  uint lo = 0u, hi = pp.emitter_count;
  while (lo < hi) {
    uint mid = (lo + hi) / 2u;
    if (u < emitters[mid].cdf) hi = mid;
    else lo = mid + 1u;
  }
  if (lo == pp.emitter_count) {
    for (uint k = pp.emitter_count; k-- > 0u;)
      if (emitters[k].pick > 0.0) return k;
  }
  return lo;
}

uint find_emitter(uint instance, uint primitive) {
  uint first = emitter_first[instance];
  return first == kNoIndex ? kNoIndex : first + primitive;
}

float area_light_pdf(uint k, vec3 p, vec3 q) {
  GpuEmitter e = emitters[k];
  if (!(e.area > 0.0)) return 0.0;
  vec3 d = q - p;
  float dist2 = dot3(d, d);
  if (!(dist2 > 0.0)) return 0.0;
  float cos_l = abs(dot3(e.normal, d)) / sqrt(dist2);
  if (!(cos_l > 0.0)) return 0.0;
  float pdf = e.pick / e.area * dist2 / cos_l;
  return pdf;
}

AreaLightSample sample_emitter_triangle(uint k, vec3 p, float u1, float u2) {
  AreaLightSample s;
  GpuEmitter e = emitters[k];
  float r = sqrt(u1);
  float b1 = 1.0 - r, b2 = u2 * r;
  vec3 position = (e.p0 + b1 * e.e1) + b2 * e.e2;
  s.position = position;
  s.emission = e.emission;
  s.to_light = vec3(0.0);
  s.distance = 0.0;
  s.pdf = 0.0;
  vec3 d = s.position - p;
  float dist = length3(d);
  if (!(dist > 0.0) || isinf(dist) || isnan(dist)) return s;
  s.distance = dist;
  vec3 to_light = d / dist;
  s.to_light = to_light;
  float cos_l = abs(dot3(e.normal, s.to_light));
  if (!(cos_l > 0.0)) return s;
  float pdf = e.pick / e.area * dist * dist / cos_l;
  s.pdf = isinf(pdf) || isnan(pdf) ? 0.0 : pdf;
  return s;
}

float power_heuristic(float a, float b) {
  a = a > 0.0 ? a : 0.0;
  b = b > 0.0 ? b : 0.0;
  if (a == b) return 0.5;
  if (a == 0.0 || isinf(b)) return 0.0;
  if (b == 0.0 || isinf(a)) return 1.0;
  float r = b / a;
  float w = 1.0 / (1.0 + r * r);
  return w;
}

// ---- queues and shadow slots ---------------------------------------------------------------------

// Queue `q` of the paths (0 or 1): appended to by path_eye, path_shade and path_trace.
void push_path(uint q, uint i) {
  uint slot = atomicAdd(counters.queue_count[q], 1u);
  if (slot < params.node_capacity) queues[q * params.node_capacity + slot] = i;
}

// The next shadow slot of path i (its own range of pp.shadow_slots), traced by frame_shadow.
void add_shadow(uint i, inout uint count, vec3 origin, vec3 direction, float tfar, vec3 value) {
  if (count >= pp.shadow_slots) {
    atomicAdd(counters.dropped, 1u);
    return;
  }
  uint s = i * pp.shadow_slots + count;
  ++count;
  GpuShadowRay r;
  r.origin = origin;
  r.tfar = tfar;
  r.direction = direction;
  r.value = value;
  r.status = kShadows ? kRayPending : kRayDone;
  r.visible = kShadows ? 0u : 1u;
  shadows[s] = r;
#ifndef SPECULA_PATH_SINGLE // the single kernel traces a path's slots itself, in order
  if (kShadows) {
    uint slot = atomicAdd(counters.shadow_queue_count[0], 1u);
    if (slot < params.shadow_capacity) shadow_queues[slot] = s;
  }
#endif
}

#endif
