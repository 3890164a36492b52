#version 460
// Single kernel: one invocation per pixel walks its Whitted tree depth first, in a bounded loop,
// over a fixed stack of kStackFrames frames kept in a buffer (not registers), so that a walk cut
// short by the traversal budget, or by its own step bound, resumes in the next dispatch exactly
// where it stopped. Each frame folds into its parent when complete: its starting radiance plus
// its visible shadow rays in light order, then its refraction child, then its reflection child ×
// their weights, the CPU's order. A child that would need a frame beyond the stack (max_depth ≥
// kStackFrames) is not traced and is counted as dropped. A trace that uses up the budget saves its
// walk in the pixel's pool slot (trace_pool.glsl) and goes on from there in the next dispatch. In
// hybrid mode (kRasterPrimary) a walk's primary hit comes from the raster pass where
// include/visibility.glsl settles it.
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/frame_common.glsl"
#include "include/visibility.glsl"

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 15) buffer FrameStack { GpuStackFrame stack[]; };
// Per chunk pixel: the top frame's index, kWalkNew before the walk starts, kWalkDone after.
layout(std430, set = 0, binding = 17) buffer FrameWalks { uint walk_top[]; };
layout(push_constant) uniform SinglePush { uint parity; uint depth; uint count; } pc;

const uint kWalkNew = 0xFFFFFFFFu;
const uint kWalkDone = 0xFFFFFFFEu;
// Steps of the walk per dispatch (each trace also draws on params.budget).
const uint kMaxSteps = 512u;

void init_frame(uint f, vec3 origin, vec3 direction, vec3 throughput, float weight, uint depth,
                uint kind, uint leaves) {
  stack[f].origin = origin;
  stack[f].direction = direction;
  stack[f].throughput = throughput;
  stack[f].weight = weight;
  stack[f].depth = depth;
  stack[f].kind = kind;
  stack[f].radiance = vec3(0.0);
  stack[f].light = 0u;
  stack[f].reflect_weight = 0.0;
  stack[f].refract_weight = 0.0;
  stack[f].state = kFrameTrace;
  stack[f].seen = 0u;
  stack[f].rays = kind == kKindPrimary ? 0u : 1u;
  stack[f].hit_entity = kNoIndex;
  stack[f].hit_t = kInfinity;
  stack[f].leaves = leaves;
  stack[f].answer = kAnswerTrace;
  stack[f].reflect_leaves = kNoIndex;
  stack[f].refract_leaves = kNoIndex;
  stack[f].resume = 0u;
}

// Frame f's trace of the pixel `local`: started, or continued where the previous dispatch's
// budget stopped it; stopped again, it is saved in the pixel's slot.
uint walk_trace(uint f, uint local, vec3 org, vec3 dir, float tfar, bool any_hit,
                inout uint budget) {
  uint status = pool_trace(stack[f].resume != 0u ? local : kNoIndex, org, dir, 0.0, tfar, any_hit,
                           budget);
  stack[f].resume = 0u;
  if (status == kRayBudget) {
    pool_store(local);
    stack[f].resume = 1u;
  }
  return status;
}

// Whether a child leaving `leaves` may be looked up now. A march-mode lookup runs up to
// kCubeMarchIterations loop iterations, drawn from the traversal budget like a trace's (lavapipe's
// loop cap); with too little left the walk stops and the next dispatch retries with a fresh
// budget, where the march always runs (even beyond a budget smaller than the march: at most one
// march past it per dispatch).
bool march_fits(uint leaves, inout uint budget) {
  if (!kCache || leaves == kNoIndex) return true;
  GpuCube c = cubes[leaves];
  if ((c.flags & kCubeEnabled) == 0u || c.mode != kCubeMarch) return true;
  if (budget < kCubeMarchIterations && budget != params.budget) return false;
  budget -= min(budget, kCubeMarchIterations);
  return true;
}

// Pushes a child of frame f when its throughput passes min_weight; false when none was pushed.
// A child leaving a cached object is looked up first (the CPU asks the store before tracing it):
// served, it returns at once; a cached miss confirms with an occlusion ray first.
bool push_child(uint base, uint top, vec3 origin, vec3 direction, float weight, uint kind,
                uint leaves) {
  uint f = base + top;
  vec3 throughput = stack[f].throughput * weight;
  if (max_component(throughput) < params.min_weight) return false;
  if (top + 1u >= kStackFrames) {
    atomicAdd(counters.dropped, 1u);
    return false;
  }
  init_frame(f + 1u, origin, direction, throughput, weight, stack[f].depth + 1u, kind, leaves);
  if (kCache && leaves != kNoIndex) {
    vec3 cached;
    uint seen;
    uint pixel = params.first_pixel + base / kStackFrames;
    uint answer = cache_lookup(leaves, pixel, stack[f].depth + 1u, origin, direction, cached, seen);
    stack[f + 1u].answer = answer;
    if ((answer & 15u) != kAnswerTrace) {
      stack[f + 1u].radiance = cached;
      stack[f + 1u].seen = seen;
    }
    if ((answer & 15u) == kAnswerUse) {
      stack[f + 1u].rays = 0u;
      stack[f + 1u].state = kFrameReturn;
    } else if ((answer & 15u) == kAnswerUseIfClear) {
      stack[f + 1u].state = kFrameConfirm;
    }
  }
  return true;
}

void main() {
  uint local = gl_GlobalInvocationID.x;
  if (local >= params.chunk_pixels) return;
  uint pixel = params.first_pixel + local;
  uint top = walk_top[local];
  if (top == kWalkDone) return;
  uint base = local * kStackFrames;
  if (top == kWalkNew) {
    top = 0u;
    init_frame(base, params.camera_origin,
               camera_direction(pixel % params.width, pixel / params.width), vec3(1.0), 1.0, 0u,
               kKindPrimary, kNoIndex);
    primary_instance[pixel] = kNoIndex;
  }
  uint budget = params.budget;
  bool stopped = false; // by the budget: every other way out of the loop returns
  uint step = 0u;
  for (; step < kMaxSteps; ++step) {
    uint f = base + top;
    uint state = stack[f].state;
    if (state == kFrameTrace) {
      GpuHit hit;
      hit.instance = kNoIndex;
      // Hybrid mode: the primary hit from the raster pass where it settles one (asked once: a
      // trace already under way resumes from the pool).
      bool settled = kRasterPrimary && stack[f].depth == 0u && stack[f].resume == 0u &&
                     visibility_hit(pixel, stack[f].origin, stack[f].direction, hit);
      if (!settled) {
        if (walk_trace(f, local, stack[f].origin, stack[f].direction, kInfinity, false, budget) !=
            kRayDone) {
          stopped = true;
          break;
        }
        hit = trace_result();
      }
      atomicAdd(counters.rays[stack[f].kind], 1u);
      if (stack[f].depth == 0u) primary_instance[pixel] = hit.instance;
      stack[f].state = kFrameReturn;
      if (kCache && hit.instance != kNoIndex) {
        stack[f].hit_t = hit.t;
        stack[f].hit_entity = instances[hit.instance].entity_index;
        stack[f].seen = 1u << (stack[f].hit_entity & 31u);
      }
      if (hit.instance == kNoIndex) {
        stack[f].radiance = params.background;
      } else if (!kWhitted) {
        stack[f].radiance = cast_shading(hit, stack[f].direction, kLightCount);
      } else {
        GpuMaterial m = materials[instances[hit.instance].material];
        vec3 d = stack[f].direction;
        ShadingPoint sp = shading_point(hit, d, true);
        stack[f].radiance = m.emission;
        float diffuse = diffuse_weight(m);
        stack[f].light = kLightCount;
        if (kLightCount > 0u && diffuse > 0.0) {
          vec3 albedo = m.base_color * (diffuse * kInvPi);
          stack[f].albedo = albedo;
          stack[f].position = sp.position;
          stack[f].geometric_normal = sp.geometric_normal;
          stack[f].shading_normal = sp.shading_normal;
          stack[f].shadow_origin =
              offset_ray_origin(sp.spawn_point, sp.spawn_error, sp.geometric_normal);
          stack[f].light = 0u;
        }
        if (kSpecular && stack[f].depth < params.max_depth) {
          SpecularSplit split = split_specular(m, sp, d, kDielectrics);
          stack[f].reflect_weight = split.reflect_weight;
          stack[f].reflect_direction = split.reflect_direction;
          stack[f].reflect_origin =
              offset_ray_origin(sp.spawn_point, sp.spawn_error, sp.geometric_normal);
          stack[f].refract_weight = split.refract_weight;
          stack[f].refract_direction = split.refract_direction;
          stack[f].refract_origin =
              offset_ray_origin(sp.spawn_point, sp.spawn_error, -sp.geometric_normal);
          stack[f].reflect_leaves = cache_leaves(hit.instance, sp.front_face);
          stack[f].refract_leaves = cache_leaves(hit.instance, !sp.front_face);
        }
        stack[f].state = kFrameShadows;
      }
    } else if (state == kFrameShadows) {
      // One light per step, so that a budget cut resumes at this light.
      uint l = stack[f].light;
      if (l >= kLightCount) {
        stack[f].state = kFrameRefract;
        continue;
      }
      float tfar;
      vec3 to_light, value;
      if (punctual_shadow_ray(lights[l], stack[f].position, stack[f].geometric_normal,
                              stack[f].shading_normal, stack[f].shadow_origin, stack[f].albedo,
                              tfar, to_light, value)) {
        bool occluded = false;
        if (kShadows) {
          if (walk_trace(f, local, stack[f].shadow_origin, to_light, tfar, true, budget) !=
              kRayDone) {
            stopped = true;
            break;
          }
          occluded = tr_occluded;
          atomicAdd(counters.rays[kKindShadow], 1u);
          if (kCache) stack[f].rays += 1u;
        }
        if (!occluded) {
          vec3 r = stack[f].radiance + value;
          stack[f].radiance = r;
        }
      }
      stack[f].light = l + 1u;
    } else if (state == kFrameRefract) {
      if (kDielectrics && stack[f].refract_weight > 0.0 &&
          !march_fits(stack[f].refract_leaves, budget)) {
        stopped = true;
        break;
      }
      stack[f].state = kFrameReflect;
      if (kDielectrics && stack[f].refract_weight > 0.0 &&
          push_child(base, top, stack[f].refract_origin, stack[f].refract_direction,
                     stack[f].refract_weight, kKindRefraction, stack[f].refract_leaves))
        ++top;
    } else if (state == kFrameReflect) {
      if (stack[f].reflect_weight > 0.0 && !march_fits(stack[f].reflect_leaves, budget)) {
        stopped = true;
        break;
      }
      stack[f].state = kFrameReturn;
      if (stack[f].reflect_weight > 0.0 &&
          push_child(base, top, stack[f].reflect_origin, stack[f].reflect_direction,
                     stack[f].reflect_weight, kKindReflection, stack[f].reflect_leaves))
        ++top;
    } else if (kCache && state == kFrameConfirm) {
      // As frame_trace.comp: clear, the cached miss is used; blocked, the ray is traced.
      if (walk_trace(f, local, stack[f].origin, stack[f].direction, kInfinity, true, budget) !=
          kRayDone) {
        stopped = true;
        break;
      }
      atomicAdd(counters.rays[kKindShadow], 1u);
      if (!tr_occluded) {
        stack[f].answer = kAnswerUse | kAnswerLookedUp;
        stack[f].rays = 1u;
        stack[f].state = kFrameReturn;
      } else {
        stack[f].answer = kAnswerTrace | kAnswerLookedUp;
        stack[f].rays = 2u;
        stack[f].radiance = vec3(0.0);
        stack[f].seen = 0u;
        stack[f].state = kFrameTrace;
      }
    } else { // kFrameReturn
      if (top == 0u) {
        write_pixel(pixel, stack[f].radiance);
        walk_top[local] = kWalkDone;
        return;
      }
      vec3 r = stack[f - 1u].radiance + vec3(stack[f].weight) * stack[f].radiance;
      stack[f - 1u].radiance = r;
      if (kCache) {
        stack[f - 1u].seen |= stack[f].seen;
        stack[f - 1u].rays += stack[f].rays;
        if (stack[f].leaves != kNoIndex)
          cache_record(stack[f].leaves, stack[f].origin, stack[f].direction, pixel,
                       stack[f].radiance, stack[f].hit_t, stack[f].hit_entity, stack[f].seen,
                       stack[f].rays, stack[f].depth, stack[f].kind, stack[f].answer,
                       stack[f].throughput);
      }
      --top;
    }
  }
  // Out of budget or steps: resumed by the next dispatch. Leaving the loop any other way means
  // the driver ended it (the walk still resumes: its state is in the buffer).
  if (!stopped && step < kMaxSteps) atomicAdd(counters.cut, 1u);
  walk_top[local] = top;
  atomicAdd(counters.pending, 1u);
  atomicAdd(counters.resumed, 1u);
}
