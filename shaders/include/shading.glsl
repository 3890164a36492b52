// Shading on the device, mirroring engine/trace/shading.h, lights.h, optics.h and
// geometry/ray_offset.h line by line (same operations in the same order, none fused: common.glsl).
// Needs trace.glsl (the scene's buffers) and frame_layout.h included first.
#ifndef SPECULA_SHADING_GLSL
#define SPECULA_SHADING_GLSL

layout(std430, set = 0, binding = 8) readonly buffer FrameParamsBuffer { GpuFrameParams params; };
layout(std430, set = 0, binding = 9) readonly buffer FrameMaterials { GpuMaterial materials[]; };
layout(std430, set = 0, binding = 10) readonly buffer FrameLights { GpuLight lights[]; };
layout(std430, set = 0, binding = 11) readonly buffer FrameNormals { float normals[]; };
layout(std430, set = 0, binding = 12) coherent buffer FrameCountersBuffer { GpuFrameCounters counters; };
layout(std430, set = 0, binding = 13) writeonly buffer FrameImage { vec4 image[]; };
layout(std430, set = 0, binding = 14) writeonly buffer FramePrimary { uint primary_instance[]; };

const float kInvPi = 0.318309886183790671538;
const float kMaxIrradiance = 1e30;
const float kInfinity = 1.0 / 0.0;
const float kLargest = 3.402823466e38;
const uint kKindPrimary = 0u;
const uint kKindShadow = 1u;
const uint kKindReflection = 2u;
const uint kKindRefraction = 3u;

// ---- Small exact helpers (GLM's arithmetic) ------------------------------------------------------

float dot3(vec3 a, vec3 b) {
  float r = (a.x * b.x + a.y * b.y) + a.z * b.z;
  return r;
}
vec3 normalize3(vec3 v) {
  float inv = 1.0 / sqrt(dot3(v, v));
  vec3 r = v * inv;
  return r;
}
float length3(vec3 v) {
  float r = sqrt(dot3(v, v));
  return r;
}
float max_component(vec3 v) { return max(v.x, max(v.y, v.z)); }
vec3 cross3(vec3 a, vec3 b) {
  vec3 r = vec3(a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y);
  return r;
}
vec3 mul_point(mat4 m, vec3 p) {
  // GLM's mat4 × vec4: columns scaled and summed in order.
  vec4 r = m[0] * p.x + m[1] * p.y;
  vec4 s = r + m[2] * p.z;
  vec4 t = s + m[3];
  return t.xyz;
}
vec3 mul3(vec3 c0, vec3 c1, vec3 c2, vec3 v) {
  vec3 r = c0 * v.x + c1 * v.y;
  vec3 s = r + c2 * v.z;
  return s;
}
bool finite3(vec3 v) { return !any(isnan(v)) && !any(isinf(v)); }

vec3 scene_normal(uint i) { return vec3(normals[3 * i], normals[3 * i + 1], normals[3 * i + 2]); }
uvec3 scene_triangle(uint i) { return uvec3(triangles[3 * i], triangles[3 * i + 1], triangles[3 * i + 2]); }

// ---- ray_offset.h --------------------------------------------------------------------------------

float gamma_bound(int n) {
  const float u = 5.9604644775390625e-8; // 2^-24
  return (float(n) * u) / (1.0 - float(n) * u);
}

vec3 barycentric_error(vec3 p0, vec3 p1, vec3 p2, float b0, float b1, float b2) {
  vec3 largest = max(abs(p0), max(abs(p1), abs(p2)));
  float magnitude = max(largest.x, max(largest.y, largest.z));
  vec3 s = (abs(b0 * p0) + abs(b1 * p1)) + abs(b2 * p2);
  vec3 r = gamma_bound(7) * s + vec3(gamma_bound(8) * magnitude);
  return r;
}

vec3 transformed_error(mat4 m, vec3 p, vec3 p_error) {
  vec3 a0 = abs(m[0].xyz), a1 = abs(m[1].xyz), a2 = abs(m[2].xyz);
  vec3 abs_t = abs(m[3].xyz);
  vec3 r = (gamma_bound(3) + 1.0) * mul3(a0, a1, a2, p_error) +
                   gamma_bound(3) * (mul3(a0, a1, a2, abs(p)) + abs_t);
  return r;
}

const float kEdgeInset = 4.0;

vec3 inset_barycentrics(vec3 p0, vec3 p1, vec3 p2, float u, float v, float margin) {
  u = clamp(u, 0.0, 1.0);
  v = clamp(v, 0.0, 1.0);
  if (u + v > 1.0) {
    float sum = u + v;
    u /= sum;
    v /= sum;
  }
  float w0 = 1.0 - u - v;
  vec3 b = vec3(max(0.0, w0), u, v);
  vec3 e0 = p2 - p1, e1 = p0 - p2, e2 = p1 - p0;
  vec3 c = cross3(e2, p2 - p0);
  float c2 = dot3(c, c);
  float m2 = margin * margin;
  float t0 = b.x * b.x * c2, t1 = b.y * b.y * c2, t2 = b.z * b.z * c2;
  float q0 = m2 * dot3(e0, e0), q1 = m2 * dot3(e1, e1), q2 = m2 * dot3(e2, e2);
  if (c2 > 1e-30 && c2 < 1e30 && t0 >= q0 && t1 >= q1 && t2 >= q2) return b;
  // In double, as the CPU: the altitudes of a thin triangle far from the origin lose digits.
  dvec3 d0 = dvec3(p0), d1 = dvec3(p1), d2 = dvec3(p2);
  dvec3 dc = cross(d1 - d0, d2 - d0);
  double twice_area = sqrt(dot(dc, dc));
  if (!(twice_area > 0.0LF) || !(margin > 0.0)) return b;
  dvec3 l = dvec3(length(d2 - d1), length(d0 - d2), length(d1 - d0));
  dvec3 lower = double(margin) / twice_area * l;
  double floor_sum = lower.x + lower.y + lower.z;
  if (!(floor_sum < 1.0LF)) return vec3(1.0 / 3.0);
  double deficit = 0.0LF, room = 0.0LF;
  for (int i = 0; i < 3; ++i) {
    if (double(b[i]) < lower[i])
      deficit += lower[i] - double(b[i]);
    else
      room += double(b[i]) - lower[i];
  }
  if (deficit == 0.0LF) return b;
  double keep = 1.0LF - deficit / room;
  dvec3 outv;
  for (int i = 0; i < 3; ++i)
    outv[i] = double(b[i]) < lower[i] ? lower[i] : lower[i] + (double(b[i]) - lower[i]) * keep;
  return vec3(outv);
}

float next_float_up(float x) {
  if (isinf(x) && x > 0.0) return x;
  if (x == 0.0) return uintBitsToFloat(1u);
  uint u = floatBitsToUint(x);
  return uintBitsToFloat(x > 0.0 ? u + 1u : u - 1u);
}
float next_float_down(float x) {
  if (isinf(x) && x < 0.0) return x;
  if (x == 0.0) return -uintBitsToFloat(1u);
  uint u = floatBitsToUint(x);
  return uintBitsToFloat(x > 0.0 ? u - 1u : u + 1u);
}

vec3 offset_ray_origin(vec3 p, vec3 p_error, vec3 n) {
  float d = dot3(abs(n), p_error);
  vec3 offset = d * n;
  vec3 po = p + offset;
  vec3 r = po;
  for (int i = 0; i < 3; ++i) {
    if (n[i] > 0.0) r[i] = next_float_up(r[i]);
    else if (n[i] < 0.0) r[i] = next_float_down(r[i]);
  }
  return r;
}

// ---- shading_point (trace/shading.h) -------------------------------------------------------------

struct ShadingPoint {
  vec3 position;
  vec3 spawn_point;
  vec3 spawn_error;
  vec3 geometric_normal;
  vec3 shading_normal;
  bool front_face;
};

vec3 interpolate(float w, float u, float v, vec3 a, vec3 b, vec3 c) {
  vec3 r = (w * a + u * b) + v * c;
  return r;
}

ShadingPoint shading_point(GpuHit hit, vec3 direction, bool with_error_bound) {
  GpuInstance inst = instances[hit.instance];
  GpuMesh mesh = meshes[inst.mesh];
  uvec3 tri = scene_triangle(mesh.first_triangle + hit.primitive);
  float w = 1.0 - hit.u - hit.v;
  vec3 p0 = scene_position(mesh.first_vertex + tri.x);
  vec3 p1 = scene_position(mesh.first_vertex + tri.y);
  vec3 p2 = scene_position(mesh.first_vertex + tri.z);
  vec3 p_object = interpolate(w, hit.u, hit.v, p0, p1, p2);
  bool identity = (inst.flags & kInstanceIdentity) != 0u;
  mat4 m = inst.world_from_object;
  ShadingPoint sp;
  sp.position = identity ? p_object : mul_point(m, p_object);
  if (with_error_bound && identity) {
    vec3 hit_error = (gamma_bound(3) + 1.0) * barycentric_error(p0, p1, p2, w, hit.u, hit.v) +
                             gamma_bound(3) * abs(p_object);
    vec3 b = inset_barycentrics(p0, p1, p2, hit.u, hit.v, kEdgeInset * length3(hit_error));
    if (b == vec3(w, hit.u, hit.v)) {
      sp.spawn_point = p_object;
      sp.spawn_error = hit_error;
    } else {
      vec3 q = interpolate(b.x, b.y, b.z, p0, p1, p2);
      vec3 q_error = (gamma_bound(3) + 1.0) * barycentric_error(p0, p1, p2, b.x, b.y, b.z) +
                             gamma_bound(3) * abs(q);
      sp.spawn_point = q;
      sp.spawn_error = q_error;
    }
  } else if (with_error_bound) {
    vec3 hit_error = transformed_error(m, p_object, barycentric_error(p0, p1, p2, w, hit.u, hit.v));
    vec3 b = inset_barycentrics(mul_point(m, p0), mul_point(m, p1), mul_point(m, p2), hit.u, hit.v,
                                kEdgeInset * length3(hit_error));
    if (b == vec3(w, hit.u, hit.v)) {
      sp.spawn_point = sp.position;
      sp.spawn_error = hit_error;
    } else {
      vec3 q_object = interpolate(b.x, b.y, b.z, p0, p1, p2);
      sp.spawn_point = mul_point(m, q_object);
      sp.spawn_error = transformed_error(m, q_object, barycentric_error(p0, p1, p2, b.x, b.y, b.z));
    }
  } else {
    sp.spawn_point = sp.position;
    sp.spawn_error = vec3(0.0);
  }
  vec3 c0 = inst.normal_from_object[0].xyz, c1 = inst.normal_from_object[1].xyz,
       c2 = inst.normal_from_object[2].xyz;
  vec3 ng = vec3(hit.ng_x, hit.ng_y, hit.ng_z);
  vec3 normal = normalize3(identity ? ng : mul3(c0, c1, c2, ng));
  sp.front_face = dot3(normal, direction) < 0.0;
  sp.geometric_normal = sp.front_face ? normal : -normal;
  sp.shading_normal = sp.geometric_normal;
  if ((inst.flags & kInstanceSmooth) != 0u && mesh.first_normal != kNoIndex) {
    vec3 n_object = interpolate(w, hit.u, hit.v, scene_normal(mesh.first_normal + tri.x),
                                scene_normal(mesh.first_normal + tri.y),
                                scene_normal(mesh.first_normal + tri.z));
    vec3 ns = identity ? n_object : mul3(c0, c1, c2, n_object);
    float len = length3(ns);
    if (len > 0.0 && !isinf(len) && !isnan(len)) {
      ns /= len;
      sp.shading_normal = dot3(ns, sp.geometric_normal) < 0.0 ? -ns : ns;
    }
  }
  return sp;
}

// ---- lights.h ------------------------------------------------------------------------------------

struct LightSample {
  vec3 to_light;
  float distance;
  vec3 irradiance;
};

// sample_light, with the distance in double as the CPU computes it.
LightSample sample_light(GpuLight light, vec3 p) {
  LightSample s;
  s.to_light = vec3(0.0);
  s.distance = kInfinity;
  s.irradiance = vec3(0.0);
  if (light.type == kLightDirectional) {
    s.to_light = -light.direction;
    s.irradiance = light.intensity;
    return s;
  }
  vec3 d = light.position - p;
  double dist = sqrt(double(d.x) * d.x + double(d.y) * d.y + double(d.z) * d.z);
  if (!(dist > 0.0LF)) return s;
  s.distance = float(dist);
  s.to_light = vec3(dvec3(d) / dist);
  double attenuation = 1.0LF;
  if (light.range > 0.0) {
    double r = dist / light.range;
    double w = clamp(1.0LF - r * r * r * r, 0.0LF, 1.0LF);
    attenuation *= w * w;
  }
  if (light.type == kLightSpot) {
    float cos_angle = dot3(-s.to_light, light.direction);
    float span = max(light.cos_inner - light.cos_outer, 1e-6);
    float t = clamp((cos_angle - light.cos_outer) / span, 0.0, 1.0);
    attenuation *= double(t * t);
  }
  dvec3 e = dvec3(light.intensity) * attenuation / dist / dist;
  s.irradiance = vec3(min(e, dvec3(kMaxIrradiance)));
  return s;
}

// ---- optics.h and split_specular -----------------------------------------------------------------

vec3 reflect_direction(vec3 d, vec3 n) {
  vec3 r = d - 2.0 * dot3(d, n) * n;
  return r;
}

// Returns false on total internal reflection.
bool refract_direction(vec3 d, vec3 n, float eta, out vec3 t) {
  t = vec3(0.0);
  float cos_i = -dot3(d, n);
  float sin2_t = eta * eta * max(0.0, 1.0 - cos_i * cos_i);
  if (sin2_t >= 1.0) return false;
  float cos_t = sqrt(1.0 - sin2_t);
  vec3 r = eta * d + (eta * cos_i - cos_t) * n;
  t = normalize3(r);
  return true;
}

float fresnel_dielectric(float cos_i, float eta) {
  cos_i = clamp(cos_i, 0.0, 1.0);
  float sin2_t = eta * eta * (1.0 - cos_i * cos_i);
  if (sin2_t >= 1.0) return 1.0;
  float cos_t = sqrt(1.0 - sin2_t);
  float r_par = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
  float r_perp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
  float f = 0.5 * (r_par * r_par + r_perp * r_perp);
  return f;
}

struct SpecularSplit {
  float reflect_weight;
  vec3 reflect_direction;
  float refract_weight;
  vec3 refract_direction;
};

SpecularSplit split_specular(GpuMaterial m, ShadingPoint sp, vec3 d, bool dielectrics) {
  SpecularSplit split;
  split.reflect_weight = m.reflectivity;
  split.reflect_direction = vec3(0.0);
  split.refract_weight = 0.0;
  split.refract_direction = vec3(0.0);
  if (dielectrics && m.transmission > 0.0) {
    float eta = sp.front_face ? 1.0 / m.ior : m.ior;
    float cos_i = -dot3(d, sp.shading_normal);
    vec3 t;
    bool ok = refract_direction(d, sp.shading_normal, eta, t);
    if (ok && dot3(t, sp.geometric_normal) >= 0.0) {
      ok = refract_direction(d, sp.geometric_normal, eta, t);
      cos_i = -dot3(d, sp.geometric_normal);
    }
    if (ok) {
      float f = fresnel_dielectric(cos_i, eta);
      float rw = split.reflect_weight + m.transmission * f;
      float tw = m.transmission * (1.0 - f);
      split.reflect_weight = rw;
      split.refract_weight = tw;
      split.refract_direction = t;
    } else {
      split.reflect_weight += m.transmission;
    }
  }
  if (split.reflect_weight > 0.0) {
    vec3 r = reflect_direction(d, sp.shading_normal);
    if (dot3(r, sp.geometric_normal) <= 0.0) r = reflect_direction(d, sp.geometric_normal);
    split.reflect_direction = normalize3(r);
  }
  return split;
}

float diffuse_weight(GpuMaterial m) { return max(0.0, 1.0 - m.reflectivity - m.transmission); }

// punctual_shadow_ray: false when the light cannot light the point.
bool punctual_shadow_ray(GpuLight light, vec3 position, vec3 geometric_normal, vec3 shading_normal,
                         vec3 origin, vec3 albedo, out float tfar, out vec3 to_light,
                         out vec3 value) {
  tfar = 0.0;
  to_light = vec3(0.0);
  value = vec3(0.0);
  LightSample ls = sample_light(light, position);
  if (dot3(ls.to_light, geometric_normal) <= 0.0) return false;
  float cos_theta = dot3(ls.to_light, shading_normal);
  if (cos_theta <= 0.0 || max_component(ls.irradiance) <= 0.0) return false;
  if (isinf(ls.distance)) {
    tfar = ls.distance;
  } else {
    dvec3 dl = dvec3(light.position - origin);
    tfar = float(sqrt(dot(dl, dl)) * (1.0LF - 1e-5LF));
  }
  to_light = ls.to_light;
  vec3 v = albedo * ls.irradiance * cos_theta;
  value = v;
  return true;
}

// Cast mode's local shading (cast_integrator.cpp): emission + base colour / π × Σ irradiance ×
// cos θ over every light, no shadow rays. `lights_used` bounds the light loop (a specialisation).
vec3 cast_shading(GpuHit hit, vec3 direction, uint light_count) {
  GpuMaterial m = materials[instances[hit.instance].material];
  ShadingPoint sp = shading_point(hit, direction, false);
  vec3 sum = vec3(0.0);
  for (uint l = 0u; l < light_count; ++l) {
    LightSample ls = sample_light(lights[l], sp.position);
    if (dot3(ls.to_light, sp.geometric_normal) <= 0.0) continue;
    float cos_theta = dot3(ls.to_light, sp.shading_normal);
    if (cos_theta <= 0.0 || max_component(ls.irradiance) <= 0.0) continue;
    sum = sum + ls.irradiance * cos_theta;
  }
  vec3 albedo = m.base_color * kInvPi;
  vec3 r = m.emission + albedo * sum;
  return r;
}

// The camera ray through pixel (x, y) (trace/camera_rays.h: normalize((forward + sx·right) +
// sy·up)).
vec3 camera_direction(uint x, uint y) {
  float sx = 2.0 * (float(x) + 0.5) * params.inv_width - 1.0;
  float sy = 1.0 - 2.0 * (float(y) + 0.5) * params.inv_height;
  vec3 column = params.camera_forward + sx * params.camera_right;
  vec3 d = column + sy * params.camera_up;
  return normalize3(d);
}

void write_pixel(uint pixel, vec3 radiance) {
  if (!finite3(radiance)) {
    atomicAdd(counters.nonfinite, 1u);
    radiance = vec3(0.0);
  }
  image[pixel] = vec4(radiance, 1.0);
}

#endif
