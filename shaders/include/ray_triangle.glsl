// The ray and the triangle test of every traversal (trace.glsl), on their own so that a kernel can
// test triangles without the scene's buffers (probe_triangle.comp against the CPU's test).
// Mirrors engine/accel/common/ray_query.h with `precise` wherever the C++ build rounds each
// operation on its own: results are bit-identical to it.
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

PreparedRay prepare_ray(vec3 org, vec3 dir, float tnear, float tfar) {
  PreparedRay r;
  r.org = org;
  r.dir = dir;
  r.tnear = tnear;
  r.tfar = tfar;
  precise vec3 inv = vec3(1.0) / dir;
  r.inv_dir = inv;
  r.neg = floatBitsToUint(dir) >> 31;
  vec3 ad = abs(dir);
  r.kz = ad.x > ad.y ? (ad.x > ad.z ? 0 : 2) : (ad.y > ad.z ? 1 : 2);
  r.kx = (r.kz + 1) % 3;
  r.ky = (r.kx + 1) % 3;
  if (dir[r.kz] < 0.0) {
    int k = r.kx;
    r.kx = r.ky;
    r.ky = k;
  }
  precise float sx = dir[r.kx] / dir[r.kz];
  precise float sy = dir[r.ky] / dir[r.kz];
  precise float sz = 1.0 / dir[r.kz];
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
  precise vec3 a = p0 - r.org;
  precise vec3 b = p1 - r.org;
  precise vec3 c = p2 - r.org;
  precise float ax = a[r.kx] - r.sx * a[r.kz];
  precise float ay = a[r.ky] - r.sy * a[r.kz];
  precise float bx = b[r.kx] - r.sx * b[r.kz];
  precise float by = b[r.ky] - r.sy * b[r.kz];
  precise float cx = c[r.kx] - r.sx * c[r.kz];
  precise float cy = c[r.ky] - r.sy * c[r.kz];
  precise float U = cx * by - cy * bx;
  precise float V = ax * cy - ay * cx;
  precise float W = bx * ay - by * ax;
  if (U == 0.0 || V == 0.0 || W == 0.0) {
    // An edge function rounded to exactly 0: all three again in double (the paper's §3.2).
    precise double Ud = double(cx) * double(by) - double(cy) * double(bx);
    precise double Vd = double(ax) * double(cy) - double(ay) * double(cx);
    precise double Wd = double(bx) * double(ay) - double(by) * double(ax);
    U = float(Ud);
    V = float(Vd);
    W = float(Wd);
  }
  if ((U < 0.0 || V < 0.0 || W < 0.0) && (U > 0.0 || V > 0.0 || W > 0.0)) return false;
  precise float det = U + V + W;
  if (det == 0.0) return false;
  precise float az = r.sz * a[r.kz];
  precise float bz = r.sz * b[r.kz];
  precise float cz = r.sz * c[r.kz];
  precise float T = U * az + V * bz + W * cz;
  // t = T / det must lie in (tnear, tmax); compare without dividing, signs folded in.
  precise float abs_det = abs(det);
  precise float signed_t = (floatBitsToUint(det) >> 31) != 0u ? -T : T;
  precise float lo = r.tnear * abs_det;
  precise float hi = tmax * abs_det;
  if (!(signed_t > lo) || !(signed_t < hi)) return false;
  precise float inv_det = 1.0 / det;
  precise float t = T * inv_det;
  if (!(t > r.tnear) || !(t < tmax)) return false; // rounding of the division at the interval ends
  precise float u = V * inv_det;
  precise float v = W * inv_det;
  t_out = t;
  u_out = u;
  v_out = v;
  return true;
}

#endif
