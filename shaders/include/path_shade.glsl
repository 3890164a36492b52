// Shading of one traced path vertex, mirroring path_integrator.cpp's shade_vertex (path mode) or
// shadow_integrator.cpp's shade_tile (kShadowMode): emission into the path's radiance, its shadow
// rays into its own slots (traced and gathered after), and in path mode the sampled continuation
// (Lambert, mirror, dielectric with Fresnel and TIR, Russian roulette from depth 3). Shared by the
// wavefront's path_shade.comp, which queues the continuation for the next depth's trace passes,
// and the single kernel path_single.comp (SPECULA_PATH_SINGLE defined), which goes on with it in
// its own loop.
#ifndef SPECULA_PATH_SHADE_GLSL
#define SPECULA_PATH_SHADE_GLSL

#include "include/path.glsl"

const uint kRouletteDepth = 3u;
const uint kSetsPerVertex = 3u;
const uint kSetBsdf = 0u, kSetLight = 1u, kSetRoulette = 2u;

// path_integrator.cpp's orthonormal_basis and cosine_direction.
void orthonormal_basis(vec3 n, out vec3 t, out vec3 b) {
  float sign = (floatBitsToUint(n.z) & 0x80000000u) != 0u ? -1.0 : 1.0; // copysign(1, n.z)
  float a = -1.0 / (sign + n.z);
  float c = n.x * n.y * a;
  vec3 tt = vec3(1.0 + sign * n.x * n.x * a, sign * c, -sign * n.x);
  vec3 bb = vec3(c, sign + n.y * n.y * a, -n.y);
  t = tt;
  b = bb;
}

vec3 cosine_direction(vec3 n, float u1, float u2) {
  float r = sqrt(u1);
  float phi = (2.0 * kPi) * u2;
  float x = r * cos(phi), y = r * sin(phi);
  float z = sqrt(max(0.0, 1.0 - u1));
  vec3 t, b;
  orthonormal_basis(n, t, b);
  vec3 d = (x * t + y * b) + z * n;
  return normalize3(d);
}

// r + a·b·w, in the CPU's order (each operation rounded on its own: common.glsl).
vec3 add_product(vec3 r, vec3 a, vec3 b, float w) {
  vec3 x = r + a * b * w;
  return x;
}

// shadow_integrator.cpp's area_light_point: the pick dimension u0 reused within the picked
// emitter's interval [cdf - pick, cdf).
float reuse_pick(float u0, float cdf, float pick) {
  float below = cdf - pick;
  float reused = clamp((u0 - below) / pick, 0.0, uintBitsToFloat(0x3f7fffffu));
  return reused;
}

void end_path(uint i, vec3 radiance, uint shadow_count) {
  paths[i].radiance = radiance;
  paths[i].shadow_count = shadow_count;
  paths[i].alive = 0u;
}

void shade_shadow_caster(uint i, GpuPath p, GpuHit hit, GpuMaterial m) {
  ShadingPoint sp = shading_point(hit, p.direction, true);
  vec3 radiance = m.emission;
  uint count = 0u;
  float diffuse = diffuse_weight(m);
  if (diffuse > 0.0) {
    vec3 albedo = m.base_color * (diffuse * kInvPi);
    vec3 origin = offset_ray_origin(sp.spawn_point, sp.spawn_error, sp.geometric_normal);
    for (uint l = 0u; l < kLightCount; ++l) {
      float tfar;
      vec3 to_light, value;
      if (punctual_shadow_ray(lights[l], sp.position, sp.geometric_normal, sp.shading_normal,
                              origin, albedo, tfar, to_light, value))
        add_shadow(i, count, origin, to_light, tfar, value);
    }
    if (kAreaLights && pp.shadow_samples > 0u) {
      uint seed = pixel_seed(p.pixel, pp.seed);
      float inv_samples = 1.0 / float(pp.shadow_samples);
      for (uint n = 0u; n < pp.shadow_samples; ++n) {
        uvec2 set = sample_set(seed, pp.sample_offset + n, 0u);
        float u0 = sample_dim(set, 0u), u1 = sample_dim(set, 1u);
        uint k = pick_emitter(u0);
        GpuEmitter e = emitters[k];
        float reused = reuse_pick(u0, e.cdf, e.pick);
        // Sampled from the shadow ray's origin, as the CPU does: its direction and distance.
        AreaLightSample ls = sample_emitter_triangle(k, origin, reused, u1);
        if (!(ls.pdf > 0.0)) continue;
        if (dot3(ls.to_light, sp.geometric_normal) <= 0.0) continue;
        float cos_theta = dot3(ls.to_light, sp.shading_normal);
        if (cos_theta <= 0.0) continue;
        float tfar = ls.distance * (1.0 - 1e-5);
        vec3 value = albedo * ls.emission * (cos_theta / ls.pdf * inv_samples);
        add_shadow(i, count, origin, ls.to_light, tfar, value);
      }
    }
  }
  end_path(i, radiance, count);
}

// Path i's vertex: p its record, its ray traced (hits[i] holds the hit).
void shade_path(uint i, GpuPath p) {
  GpuHit hit = hits[i];
  bool primary = p.depth == 0u && p.kind == kKindPrimary; // a pixel's first sample's camera ray
  if (primary) primary_instance[p.pixel] = hit.instance;
  if (kGuides && primary) {
    // integrators.h's write_guide, from the same hit.
    GpuGuide g;
    g.albedo = vec3(1.0);
    g.depth = kInfinity;
    g.normal = vec3(0.0);
    g._pad0 = 0.0;
    if (hit.instance != kNoIndex) {
      GpuMaterial gm = materials[instances[hit.instance].material];
      float diffuse = diffuse_weight(gm);
      vec3 albedo = diffuse * gm.base_color + (1.0 - diffuse);
      g.albedo = albedo;
      g.depth = hit.t;
      g.normal = shading_point(hit, p.direction, false).shading_normal;
    }
    guides[p.pixel] = g;
  }
  if (hit.instance == kNoIndex) {
    vec3 r = add_product(p.radiance, p.throughput, params.background, 1.0);
    end_path(i, kShadowMode ? params.background : r, 0u);
    return;
  }
  GpuMaterial m = materials[instances[hit.instance].material];
  if (kShadowMode) {
    shade_shadow_caster(i, p, hit, m);
    return;
  }

  vec3 d = p.direction;
  ShadingPoint sp = shading_point(hit, d, true);
  vec3 radiance = p.radiance;
  if (kAreaLights && m.emission != vec3(0.0)) {
    float weight = 1.0;
    // bsdf_pdf 0: seen by the camera or through a specular bounce, which light sampling cannot
    // reach.
    if (p.bsdf_pdf > 0.0) {
      if (kSampling == kSamplingLight) {
        weight = 0.0;
      } else if (kSampling == kSamplingMis) {
        uint e = find_emitter(hit.instance, hit.primitive);
        if (e != kNoIndex)
          weight = power_heuristic(p.bsdf_pdf, area_light_pdf(e, p.previous, sp.position));
      }
    }
    if (weight > 0.0) {
      radiance = add_product(radiance, p.throughput, m.emission, weight);
    }
  }

  float diffuse = diffuse_weight(m);
  float specular =
      (kMirrors ? m.reflectivity : 0.0) + (kDielectrics ? m.transmission : 0.0);
  float total = diffuse + specular;
  float p_diffuse = total > 0.0 ? diffuse / total : 0.0;
  bool last = p.depth >= params.max_depth;
  uint seed = pixel_seed(p.pixel, pp.seed);
  uint set = p.depth * kSetsPerVertex;
  uint count = 0u;

  vec3 origin = vec3(0.0);
  if (diffuse > 0.0) {
    origin = offset_ray_origin(sp.spawn_point, sp.spawn_error, sp.geometric_normal);
    vec3 f = m.base_color * (diffuse * kInvPi);
    for (uint l = 0u; l < kLightCount; ++l) {
      float tfar;
      vec3 to_light, value;
      if (punctual_shadow_ray(lights[l], sp.position, sp.geometric_normal, sp.shading_normal,
                              origin, f, tfar, to_light, value)) {
        vec3 v = p.throughput * value;
        add_shadow(i, count, origin, to_light, tfar, v);
      }
    }
    // Area lights are sampled towards the next vertex, which the last one does not have.
    if (kAreaLights && !last && kSampling != kSamplingBsdf) {
      uvec2 u = sample_set(seed, p.sample_index, set + kSetLight);
      uint k = pick_emitter(sample_dim(u, 0u));
      AreaLightSample ls = sample_emitter_triangle(k, sp.position, sample_dim(u, 1u),
                                                   sample_dim(u, 2u));
      float cos_theta = dot3(ls.to_light, sp.shading_normal);
      if (ls.pdf > 0.0 && dot3(ls.to_light, sp.geometric_normal) > 0.0 && cos_theta > 0.0 &&
          max_component(ls.emission) > 0.0) {
        float bsdf = p_diffuse * cos_theta * kInvPi;
        float weight = kSampling == kSamplingMis ? power_heuristic(ls.pdf, bsdf) : 1.0;
        float tfar = ls.distance * (1.0 - 1e-4);
        vec3 v = p.throughput * f * ls.emission * (cos_theta * weight / ls.pdf);
        add_shadow(i, count, origin, ls.to_light, tfar, v);
      }
    }
  }
  if (last || !(total > 0.0)) {
    end_path(i, radiance, count);
    return;
  }

  // The continuation: a lobe picked by its weight, the throughput divided by its probability.
  uvec2 u = sample_set(seed, p.sample_index, set + kSetBsdf);
  vec3 throughput = p.throughput;
  float bsdf_pdf = 0.0;
  vec3 ray_origin, direction;
  uint kind = kKindReflection;
  if (!(kMirrors || kDielectrics) || sample_dim(u, 0u) * total < diffuse) {
    vec3 wi = cosine_direction(sp.shading_normal, sample_dim(u, 2u), sample_dim(u, 3u));
    float cos_theta = dot3(wi, sp.shading_normal);
    if (dot3(wi, sp.geometric_normal) <= 0.0 || !(cos_theta > 0.0)) {
      end_path(i, radiance, count);
      return;
    }
    vec3 t = throughput * (m.base_color * total);
    throughput = t;
    float pdf = p_diffuse * cos_theta * kInvPi;
    bsdf_pdf = pdf;
    ray_origin = origin;
    direction = wi;
  } else {
    vec3 t = throughput * total;
    throughput = t;
    bool reflect = true;
    if (kDielectrics) {
      SpecularSplit split = split_specular(m, sp, d, true);
      float both = split.reflect_weight + split.refract_weight;
      reflect = sample_dim(u, 1u) * both < split.reflect_weight;
      direction = reflect ? split.reflect_direction : split.refract_direction;
    } else {
      vec3 r = reflect_direction(d, sp.shading_normal);
      if (dot3(r, sp.geometric_normal) <= 0.0) r = reflect_direction(d, sp.geometric_normal);
      direction = normalize3(r);
    }
    kind = reflect ? kKindReflection : kKindRefraction;
    ray_origin = offset_ray_origin(sp.spawn_point, sp.spawn_error,
                                   reflect ? sp.geometric_normal : -sp.geometric_normal);
  }
  if (p.depth >= kRouletteDepth) {
    float survival = clamp(max_component(throughput), 0.05, 1.0);
    if (sample_dim(sample_set(seed, p.sample_index, set + kSetRoulette), 0u) >= survival) {
      end_path(i, radiance, count);
      return;
    }
    vec3 t = throughput / survival;
    throughput = t;
  }
  if (!(max_component(throughput) > 0.0)) { // a black surface ends it
    end_path(i, radiance, count);
    return;
  }
  paths[i].radiance = radiance;
  paths[i].shadow_count = count;
  paths[i].origin = ray_origin;
  paths[i].tfar = kInfinity;
  paths[i].direction = direction;
  paths[i].throughput = throughput;
  paths[i].bsdf_pdf = bsdf_pdf;
  paths[i].previous = sp.position;
  paths[i].depth = p.depth + 1u;
  paths[i].kind = kind;
  paths[i].status = kRayPending;
#ifndef SPECULA_PATH_SINGLE
  push_path(0u, i);
#endif
}

#endif
