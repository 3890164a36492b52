// The ray and the triangle test of every traversal (trace.glsl), on their own so that a kernel can
// test triangles without the scene's buffers (probe_triangle.comp against the CPU's test).
// Mirrors engine/accel/common/ray_query.h operation for operation, each rounded on its own as in
// the C++ build (common.glsl): results are bit-identical to it.
#ifndef SPECULA_RAY_TRIANGLE_GLSL
#define SPECULA_RAY_TRIANGLE_GLSL

// ---- Rays (accel::PreparedRay) -------------------------------------------------------------------

struct PreparedRay {
  vec3 org;
  vec3 dir;
  vec3 inv_dir;
  float tnear;
  float tfar;
  int kx, ky, kz;
  float sx, sy, sz;
  uvec3 neg;
};

// Bit tests: a compiler may assume no NaN/Inf in comparisons, never in integer ops.
bool trace_finite(float x) { return (floatBitsToUint(x) & 0x7F800000u) != 0x7F800000u; }
bool trace_nan(float x) { return (floatBitsToUint(x) & 0x7FFFFFFFu) > 0x7F800000u; }
bool trace_finite3(vec3 v) { return trace_finite(v.x) && trace_finite(v.y) && trace_finite(v.z); }

// geometry/ray.h's traceable().
bool ray_valid(PreparedRay r) {
  return trace_finite3(r.org) && trace_finite3(r.dir) && !(r.dir == vec3(0.0)) &&
         !trace_nan(r.tfar) && !trace_nan(r.tnear) && r.tnear >= 0.0 && r.tnear <= r.tfar &&
         trace_finite(r.tnear);
}

// Component a of v by selects, not v[a]: indexing a vector by a per-invocation value makes
// llvmpipe spill it to memory and gather lane by lane.
float trace_axis(vec3 v, int a) { return a == 0 ? v.x : (a == 1 ? v.y : v.z); }

// (v[kx], v[ky], v[kz]) of the ray's shear frame.
vec3 ray_frame(PreparedRay r, vec3 v) {
  return vec3(trace_axis(v, r.kx), trace_axis(v, r.ky), trace_axis(v, r.kz));
}

PreparedRay prepare_ray(vec3 org, vec3 dir, float tnear, float tfar) {
  PreparedRay r;
  r.org = org;
  r.dir = dir;
  r.tnear = tnear;
  r.tfar = tfar;
  vec3 inv = vec3(1.0) / dir;
  r.inv_dir = inv;
  r.neg = floatBitsToUint(dir) >> 31;
  vec3 ad = abs(dir);
  r.kz = ad.x > ad.y ? (ad.x > ad.z ? 0 : 2) : (ad.y > ad.z ? 1 : 2);
  r.kx = (r.kz + 1) % 3;
  r.ky = (r.kx + 1) % 3;
  if (trace_axis(dir, r.kz) < 0.0) {
    int k = r.kx;
    r.kx = r.ky;
    r.ky = k;
  }
  vec3 d = ray_frame(r, dir);
  float sx = d.x / d.z;
  float sy = d.y / d.z;
  float sz = 1.0 / d.z;
  r.sx = sx;
  r.sy = sy;
  r.sz = sz;
  return r;
}

// ---- Woop, Benthin & Wald's watertight test (accel::intersect_watertight) ------------------------

bool intersect_watertight(PreparedRay r, vec3 p0, vec3 p1, vec3 p2, float tmax, out float t_out,
                          out float u_out, out float v_out) {
  t_out = 0.0;
  u_out = 0.0;
  v_out = 0.0;
  vec3 a_world = p0 - r.org;
  vec3 b_world = p1 - r.org;
  vec3 c_world = p2 - r.org;
  vec3 a = ray_frame(r, a_world);
  vec3 b = ray_frame(r, b_world);
  vec3 c = ray_frame(r, c_world);
  float ax = a.x - r.sx * a.z;
  float ay = a.y - r.sy * a.z;
  float bx = b.x - r.sx * b.z;
  float by = b.y - r.sy * b.z;
  float cx = c.x - r.sx * c.z;
  float cy = c.y - r.sy * c.z;
  float U = cx * by - cy * bx;
  float V = ax * cy - ay * cx;
  float W = bx * ay - by * ax;
  if (U == 0.0 || V == 0.0 || W == 0.0) {
    // An edge function rounded to exactly 0: all three again in double (the paper's §3.2).
    double Ud = double(cx) * double(by) - double(cy) * double(bx);
    double Vd = double(ax) * double(cy) - double(ay) * double(cx);
    double Wd = double(bx) * double(ay) - double(by) * double(ax);
    U = float(Ud);
    V = float(Vd);
    W = float(Wd);
  }
  if ((U < 0.0 || V < 0.0 || W < 0.0) && (U > 0.0 || V > 0.0 || W > 0.0)) return false;
  float det = U + V + W;
  if (det == 0.0) return false;
  float az = r.sz * a.z;
  float bz = r.sz * b.z;
  float cz = r.sz * c.z;
  float T = U * az + V * bz + W * cz;
  // t = T / det must lie in (tnear, tmax); compare without dividing, signs folded in.
  float abs_det = abs(det);
  float signed_t = (floatBitsToUint(det) >> 31) != 0u ? -T : T;
  float lo = r.tnear * abs_det;
  float hi = tmax * abs_det;
  if (!(signed_t > lo) || !(signed_t < hi)) return false;
  float inv_det = 1.0 / det;
  float t = T * inv_det;
  if (!(t > r.tnear) || !(t < tmax)) return false; // rounding of the division at the interval ends
  float u = V * inv_det;
  float v = W * inv_det;
  t_out = t;
  u_out = u;
  v_out = v;
  return true;
}

#endif
