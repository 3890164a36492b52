#version 460
// Wavefront, shading of a wave's traced rays (whitted_integrator.cpp's shade): the starting
// radiance (emission; the background on a miss), a shadow ray per light that can light the
// diffuse part, each in its own slot of a range the node owns (light order: the fold adds them
// in that order), and, below max_depth, the reflection and refraction rays above min_weight,
// appended to the node buffer and queued for the next wave. Cast mode shades locally and stops.
#extension GL_GOOGLE_include_directive : require
#include "include/common.glsl"
#include "include/frame_wavefront.glsl"

layout(local_size_x = 64) in;

// A ray leaving a cached object (`leaves`, a cube's slot) is first looked up, as the CPU asks
// the store before the next wave: served ones are done here (a cached miss still needs its
// occlusion ray, traced by frame_trace before the ray itself).
uint spawn(GpuFrameNode parent, vec3 origin, vec3 direction, float weight, uint kind,
           uint leaves) {
  vec3 throughput = parent.throughput * weight;
  if (max_component(throughput) < params.min_weight) return kNoIndex;
  uint n = atomicAdd(counters.node_count, 1u);
  if (n >= params.node_capacity) {
    atomicAdd(counters.dropped, 1u);
    return kNoIndex;
  }
  GpuFrameNode c;
  c.origin = origin;
  c.tfar = kInfinity;
  c.direction = direction;
  c.pixel = parent.pixel;
  c.throughput = throughput;
  c.depth = parent.depth + 1u;
  c.radiance = vec3(0.0);
  c.weight = weight;
  c.kind = kind;
  c.status = kRayPending;
  c.child_reflect = kNoIndex;
  c.child_refract = kNoIndex;
  c.shadow_first = 0u;
  c.shadow_count = 0u;
  c.seen = 0u;
  c.rays = 1u;
  c.leaves = leaves;
  c.answer = kAnswerTrace;
  c.resume = kNoIndex;
  c._pad1 = 0u;
  if (kCache && leaves != kNoIndex) {
    vec3 cached;
    c.answer = cache_lookup(leaves, c.pixel, c.depth, origin, direction, cached, c.seen);
    if ((c.answer & 15u) != kAnswerTrace) c.radiance = cached;
    if ((c.answer & 15u) == kAnswerUse) {
      c.rays = 0u;
      c.status = kRayDone;
      nodes[n] = c;
      return n;
    }
  }
  nodes[n] = c;
  push_ray(n);
  return n;
}

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= min(counters.queue_count[pc.parity], params.node_capacity)) return;
  uint n = queues[pc.parity * params.node_capacity + i];
  uint status = nodes[n].status;
  if (status == kRayBudget) return; // queued again by the trace kernel
  if (status != kRayDone) {
    atomicAdd(counters.cut, 1u);
    nodes[n].radiance = vec3(0.0);
    return;
  }
  GpuFrameNode node = nodes[n];
  if (kCache && (node.answer & 15u) == kAnswerUse) return; // a cached miss, confirmed clear
  GpuHit hit = hits[n];
  if (node.depth == 0u) primary_instance[node.pixel] = hit.instance;
  if (hit.instance == kNoIndex) {
    nodes[n].radiance = params.background;
    return;
  }
  if (!kWhitted) {
    nodes[n].radiance = cast_shading(hit, node.direction, kLightCount);
    return;
  }
  GpuMaterial m = materials[instances[hit.instance].material];
  vec3 d = node.direction;
  ShadingPoint sp = shading_point(hit, d, true);
  nodes[n].radiance = m.emission;
  if (kCache) nodes[n].seen = 1u << (instances[hit.instance].entity_index & 31u);

  float diffuse = diffuse_weight(m);
  if (kLightCount > 0u && diffuse > 0.0) {
    uint first = atomicAdd(counters.shadow_count, kLightCount);
    if (first + kLightCount > params.shadow_capacity) {
      atomicAdd(counters.dropped, kLightCount);
    } else {
      vec3 albedo = m.base_color * (diffuse * kInvPi);
      vec3 origin = offset_ray_origin(sp.spawn_point, sp.spawn_error, sp.geometric_normal);
      uint lit_count = 0u;
      for (uint l = 0u; l < kLightCount; ++l) {
        GpuShadowRay s;
        s.origin = origin;
        s.status = kRayDone;
        s.visible = 0u;
        bool lit = punctual_shadow_ray(lights[l], sp.position, sp.geometric_normal,
                                       sp.shading_normal, origin, albedo, s.tfar, s.direction,
                                       s.value);
        if (lit) {
          if (kShadows) s.status = kRayPending;
          else s.visible = 1u;
        }
        shadows[first + l] = s;
        if (lit && kShadows) {
          push_shadow(first + l);
          ++lit_count;
        }
      }
      if (kCache) nodes[n].rays = node.rays + lit_count; // the CPU counts each shadow ray
      nodes[n].shadow_first = first;
      nodes[n].shadow_count = kLightCount;
    }
  }
  if (!kSpecular || node.depth >= params.max_depth) return;

  SpecularSplit split = split_specular(m, sp, d, kDielectrics);
  if (split.reflect_weight > 0.0)
    nodes[n].child_reflect =
        spawn(node, offset_ray_origin(sp.spawn_point, sp.spawn_error, sp.geometric_normal),
              split.reflect_direction, split.reflect_weight, kKindReflection,
              cache_leaves(hit.instance, sp.front_face));
  if (kDielectrics && split.refract_weight > 0.0)
    nodes[n].child_refract =
        spawn(node, offset_ray_origin(sp.spawn_point, sp.spawn_error, -sp.geometric_normal),
              split.refract_direction, split.refract_weight, kKindRefraction,
              cache_leaves(hit.instance, !sp.front_face));
}
