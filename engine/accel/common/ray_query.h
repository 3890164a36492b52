#pragma once
/// \file
/// What every one of Specula's own structures (kd-tree, BVH, grid, two-level) shares: the view of
/// the triangles it is built over, a ray prepared once for traversal and for the watertight
/// triangle test, the triangle tests themselves, the conservative box test, and the hit record.
///
/// Triangle tests (numerical robustness, docs/design/watertightness.md):
///   - watertight (default): Woop, Benthin & Wald, "Watertight Ray/Triangle Intersection", JCGT
///     2013. The ray's dominant axis becomes z, the triangle is sheared into ray space, and the
///     three edge functions decide inside/outside; an edge function that rounds to exactly 0 is
///     recomputed in double precision, so a ray through a shared edge or vertex hits at least one
///     of the triangles sharing it. No epsilon anywhere.
///   - Möller–Trumbore (option): the classic test, with no tolerance on the barycentrics, so rays
///     through shared edges can leak between the two triangles.
/// Barycentrics follow Embree's convention: u weights vertex 1, v weights vertex 2.
///
/// Box test: the slab test in the form of Woop et al. §3.3 / pbrt: far distances are enlarged by
/// 1 + 2γ(3) so that rounding in the box test never culls a triangle the exact test would hit.

#include "specula/core/math.h"
#include "specula/geometry/ray.h"
#include "specula/geometry/ray_offset.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <type_traits>

namespace specula::accel {

/// Triangles a structure is built over: indices into `positions`, read in place (never copied).
struct TriangleView {
  const vec3* positions = nullptr;
  const uvec3* triangles = nullptr;
  std::uint32_t count = 0;

  [[nodiscard]] const vec3& vertex(std::uint32_t triangle, int k) const {
    return positions[triangles[triangle][k]];
  }
  [[nodiscard]] Aabb bounds(std::uint32_t triangle) const {
    Aabb b;
    for (int k = 0; k < 3; ++k) b.grow(vertex(triangle, k));
    return b;
  }
};

enum class TriangleTest : std::uint8_t { watertight, moller_trumbore };

/// Factor that makes a box's far distance conservative (Woop et al. 2013, §3.3).
inline constexpr float kBoxFarScale = 1.0f + 2.0f * gamma_bound(3);

/// A ray prepared once for a whole traversal: reciprocal direction and signs for the box tests,
/// dominant axis and shear for the watertight test. `tfar` shrinks as closer hits are found.
struct PreparedRay {
  vec3 org{0.0f};
  vec3 dir{0.0f, 0.0f, -1.0f};
  vec3 inv_dir{0.0f};
  float tnear = 0.0f;
  float tfar = std::numeric_limits<float>::infinity();
  int kx = 0, ky = 1, kz = 2; ///< kz: the dominant axis of dir
  float sx = 0.0f, sy = 0.0f, sz = 1.0f;
  std::uint32_t neg[3] = {0, 0, 0}; ///< 1 where dir is negative on that axis

  /// False when the ray cannot be traced (a NaN or infinite component, a zero direction, or an
  /// empty interval): such a ray misses everything and must not enter a traversal.
  [[nodiscard]] bool valid() const { return traceable(org, dir, tnear, tfar); }

  static PreparedRay make(const Ray& ray) { return make(ray.origin, ray.direction, ray.tnear, ray.tfar); }
  static PreparedRay make(const vec3& org, const vec3& dir, float tnear, float tfar) {
    PreparedRay r;
    r.org = org;
    r.dir = dir;
    r.tnear = tnear;
    r.tfar = tfar;
    // 1/±0 = ±inf is what the slab test wants; a NaN direction is caught by valid().
    r.inv_dir = vec3(1.0f / dir.x, 1.0f / dir.y, 1.0f / dir.z);
    for (int a = 0; a < 3; ++a) r.neg[a] = std::signbit(dir[a]) ? 1u : 0u;
    const vec3 ad = glm::abs(dir);
    r.kz = ad.x > ad.y ? (ad.x > ad.z ? 0 : 2) : (ad.y > ad.z ? 1 : 2);
    r.kx = (r.kz + 1) % 3;
    r.ky = (r.kx + 1) % 3;
    if (dir[r.kz] < 0.0f) std::swap(r.kx, r.ky); // keep the winding
    r.sx = dir[r.kx] / dir[r.kz];
    r.sy = dir[r.ky] / dir[r.kz];
    r.sz = 1.0f / dir[r.kz];
    return r;
  }
};

/// A triangle hit within a structure: `prim` indexes the structure's TriangleView.
struct TriangleHit {
  float t = std::numeric_limits<float>::infinity();
  float u = 0.0f, v = 0.0f;
  std::uint32_t prim = 0xFFFFFFFFu;
  [[nodiscard]] bool hit() const { return prim != 0xFFFFFFFFu; }
};

/// The watertight test's fallback when an edge function rounds to exactly 0 in single precision:
/// all three recomputed in double (the paper's §3.2). Kept out of line so the common path inlines.
[[gnu::noinline, gnu::cold]] inline void edge_functions_in_double(float ax, float ay, float bx,
                                                                   float by, float cx, float cy,
                                                                   float& U, float& V, float& W) {
  U = float(double(cx) * double(by) - double(cy) * double(bx));
  V = float(double(ax) * double(cy) - double(ay) * double(cx));
  W = float(double(bx) * double(ay) - double(by) * double(ax));
}

/// Woop et al.'s watertight test. On a hit with tnear < t < tmax, writes t, u, v and returns true.
[[nodiscard, gnu::always_inline]] inline bool intersect_watertight(const PreparedRay& r, const vec3& p0, const vec3& p1,
                                               const vec3& p2, float tmax, float& t_out,
                                               float& u_out, float& v_out) {
  const vec3 a = p0 - r.org;
  const vec3 b = p1 - r.org;
  const vec3 c = p2 - r.org;
  const float ax = a[r.kx] - r.sx * a[r.kz];
  const float ay = a[r.ky] - r.sy * a[r.kz];
  const float bx = b[r.kx] - r.sx * b[r.kz];
  const float by = b[r.ky] - r.sy * b[r.kz];
  const float cx = c[r.kx] - r.sx * c[r.kz];
  const float cy = c[r.ky] - r.sy * c[r.kz];
  float U = cx * by - cy * bx;
  float V = ax * cy - ay * cx;
  float W = bx * ay - by * ax;
  if (U == 0.0f || V == 0.0f || W == 0.0f) [[unlikely]]
    edge_functions_in_double(ax, ay, bx, by, cx, cy, U, V, W);
  if ((U < 0.0f || V < 0.0f || W < 0.0f) && (U > 0.0f || V > 0.0f || W > 0.0f)) return false;
  const float det = U + V + W;
  if (det == 0.0f) return false;
  const float az = r.sz * a[r.kz];
  const float bz = r.sz * b[r.kz];
  const float cz = r.sz * c[r.kz];
  const float T = U * az + V * bz + W * cz;
  // t = T / det must lie in (tnear, tmax); compare without dividing, signs folded in.
  const float abs_det = std::abs(det);
  const float signed_t = std::signbit(det) ? -T : T;
  if (!(signed_t > r.tnear * abs_det) || !(signed_t < tmax * abs_det)) return false;
  const float inv_det = 1.0f / det;
  const float t = T * inv_det;
  if (!(t > r.tnear) || !(t < tmax)) return false; // rounding of the division at the interval ends
  t_out = t;
  u_out = V * inv_det;
  v_out = W * inv_det;
  return true;
}

/// Möller–Trumbore, no tolerance on the barycentrics (an option: not watertight).
[[nodiscard]] inline bool intersect_moller_trumbore(const PreparedRay& r, const vec3& p0,
                                                    const vec3& p1, const vec3& p2, float tmax,
                                                    float& t_out, float& u_out, float& v_out) {
  const vec3 e1 = p1 - p0;
  const vec3 e2 = p2 - p0;
  const vec3 p = glm::cross(r.dir, e2);
  const float det = glm::dot(e1, p);
  if (det == 0.0f) return false;
  const float inv_det = 1.0f / det;
  const vec3 s = r.org - p0;
  const float u = glm::dot(s, p) * inv_det;
  if (!(u >= 0.0f) || u > 1.0f) return false;
  const vec3 q = glm::cross(s, e1);
  const float v = glm::dot(r.dir, q) * inv_det;
  if (!(v >= 0.0f) || u + v > 1.0f) return false;
  const float t = glm::dot(e2, q) * inv_det;
  if (!(t > r.tnear) || !(t < tmax)) return false;
  t_out = t;
  u_out = u;
  v_out = v;
  return true;
}

template <TriangleTest Test>
[[nodiscard, gnu::always_inline]] inline bool intersect_triangle(const PreparedRay& r, const vec3& p0, const vec3& p1,
                                             const vec3& p2, float tmax, float& t, float& u,
                                             float& v) {
  if constexpr (Test == TriangleTest::watertight)
    return intersect_watertight(r, p0, p1, p2, tmax, t, u, v);
  else
    return intersect_moller_trumbore(r, p0, p1, p2, tmax, t, u, v);
}

/// Tests triangle `prim` of `tris` and, on a closer hit, updates `hit` and r.tfar.
template <TriangleTest Test>
inline bool intersect_closest(PreparedRay& r, const TriangleView& tris, std::uint32_t prim,
                              TriangleHit& hit) {
  const uvec3 tri = tris.triangles[prim];
  float t, u, v;
  if (!intersect_triangle<Test>(r, tris.positions[tri.x], tris.positions[tri.y],
                                tris.positions[tri.z], r.tfar, t, u, v))
    return false;
  r.tfar = t;
  hit.t = t;
  hit.u = u;
  hit.v = v;
  hit.prim = prim;
  return true;
}

/// Whether triangle `prim` lies within (tnear, tfar) of r.
template <TriangleTest Test>
[[nodiscard]] inline bool intersect_any(const PreparedRay& r, const TriangleView& tris,
                                        std::uint32_t prim) {
  const uvec3 tri = tris.triangles[prim];
  float t, u, v;
  return intersect_triangle<Test>(r, tris.positions[tri.x], tris.positions[tri.y],
                                  tris.positions[tri.z], r.tfar, t, u, v);
}

/// The slab test against [lo, hi], conservative (far distance scaled by kBoxFarScale). On overlap
/// with (r.tnear, r.tfar) returns true and the entry and exit distances, clamped to the ray's
/// interval.
[[nodiscard]] inline bool intersect_box(const PreparedRay& r, const vec3& lo, const vec3& hi,
                                        float& t_enter, float& t_exit) {
  float t0 = r.tnear, t1 = r.tfar;
  for (int a = 0; a < 3; ++a) {
    float tn = (lo[a] - r.org[a]) * r.inv_dir[a];
    float tf = (hi[a] - r.org[a]) * r.inv_dir[a];
    if (r.neg[a]) std::swap(tn, tf);
    tf *= kBoxFarScale;
    // NaN (0 · inf: origin on a slab plane of a parallel ray) keeps the current bound.
    t0 = tn > t0 ? tn : t0;
    t1 = tf < t1 ? tf : t1;
  }
  t_enter = t0;
  t_exit = t1;
  return t0 <= t1;
}

/// The geometric normal Embree reports, (p1 - p0) × (p2 - p0), not normalised.
[[nodiscard]] inline vec3 geometric_normal(const TriangleView& tris, std::uint32_t prim) {
  const uvec3 tri = tris.triangles[prim];
  const vec3& p0 = tris.positions[tri.x];
  return glm::cross(tris.positions[tri.y] - p0, tris.positions[tri.z] - p0);
}

/// Reference: every triangle tested (tests and structural checks only).
template <TriangleTest Test = TriangleTest::watertight>
[[nodiscard]] inline TriangleHit brute_force_closest(const TriangleView& tris, PreparedRay r) {
  TriangleHit hit;
  if (!r.valid()) return hit;
  for (std::uint32_t i = 0; i < tris.count; ++i) intersect_closest<Test>(r, tris, i, hit);
  return hit;
}

/// Rays of a packet, one array per component (SoA), N = 4 or 8 (SSE / AVX2 lanes).
template <int N>
struct RayPacket {
  alignas(32) float ox[N], oy[N], oz[N];
  alignas(32) float dx[N], dy[N], dz[N];
  alignas(32) float tnear[N], tfar[N];
};

/// A packet's closest hits; prim[i] == 0xFFFFFFFF for a miss (t[i] == +inf).
template <int N>
struct PacketHits {
  alignas(32) float t[N], u[N], v[N];
  alignas(32) std::uint32_t prim[N];
  void clear() {
    for (int i = 0; i < N; ++i) {
      t[i] = std::numeric_limits<float>::infinity();
      u[i] = v[i] = 0.0f;
      prim[i] = 0xFFFFFFFFu;
    }
  }
  void set(int i, const TriangleHit& h) {
    t[i] = h.t;
    u[i] = h.u;
    v[i] = h.v;
    prim[i] = h.prim;
  }
};

/// Whether this CPU runs the AVX2 packet kernels (asked once).
[[nodiscard]] inline bool cpu_has_avx2() {
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
}

/// Lanes 4·half … 4·half + 3 of an 8-ray packet as a packet of 4.
[[nodiscard]] inline RayPacket<4> half_packet(const RayPacket<8>& rays, int half) {
  RayPacket<4> r4;
  for (int i = 0; i < 4; ++i) {
    const int j = 4 * half + i;
    r4.ox[i] = rays.ox[j], r4.oy[i] = rays.oy[j], r4.oz[i] = rays.oz[j];
    r4.dx[i] = rays.dx[j], r4.dy[i] = rays.dy[j], r4.dz[i] = rays.dz[j];
    r4.tnear[i] = rays.tnear[j], r4.tfar[i] = rays.tfar[j];
  }
  return r4;
}

/// An 8-ray packet traced as two packets of 4 by `intersect4(rays, hits, active)` (CPUs without
/// AVX2): lanes copied out and back, tfar and hits included.
template <typename Intersect4>
void as_two_packets_of_4(RayPacket<8>& rays, PacketHits<8>& hits, const bool active[8],
                         Intersect4&& intersect4) {
  for (int half = 0; half < 2; ++half) {
    RayPacket<4> r4 = half_packet(rays, half);
    PacketHits<4> h4;
    for (int i = 0; i < 4; ++i) {
      const int j = 4 * half + i;
      h4.t[i] = hits.t[j], h4.u[i] = hits.u[j], h4.v[i] = hits.v[j], h4.prim[i] = hits.prim[j];
    }
    intersect4(r4, h4, active + 4 * half);
    for (int i = 0; i < 4; ++i) {
      const int j = 4 * half + i;
      rays.tfar[j] = r4.tfar[i];
      hits.t[j] = h4.t[i], hits.u[j] = h4.u[i], hits.v[j] = h4.v[i], hits.prim[j] = h4.prim[i];
    }
  }
}

/// The triangle test as a type, for kernels compiled once per test.
template <TriangleTest Test>
using TestTag = std::integral_constant<TriangleTest, Test>;

/// A structure's intersect4 / intersect8: `kernel(rays, hits, active, TestTag<test>{})`, the
/// packet of 8 as two packets of 4 on a CPU without AVX2.
template <int N, typename Kernel>
void run_packet(RayPacket<N>& rays, PacketHits<N>& hits, const bool* active, TriangleTest test,
                const Kernel& kernel) {
  if constexpr (N == 8) {
    if (!cpu_has_avx2()) {
      as_two_packets_of_4(rays, hits, active,
                          [&](RayPacket<4>& r4, PacketHits<4>& h4, const bool* a4) {
                            run_packet(r4, h4, a4, test, kernel);
                          });
      return;
    }
  }
  if (test == TriangleTest::watertight)
    kernel(rays, hits, active, TestTag<TriangleTest::watertight>{});
  else
    kernel(rays, hits, active, TestTag<TriangleTest::moller_trumbore>{});
}

/// A structure's occluded4 / occluded8: `kernel(rays, active, TestTag<test>{})` returns the mask of
/// blocked lanes; the packet of 8 as two packets of 4 on a CPU without AVX2.
template <int N, typename Kernel>
unsigned run_occlusion_packet(const RayPacket<N>& rays, const bool* active, TriangleTest test,
                              const Kernel& kernel) {
  if constexpr (N == 8) {
    if (!cpu_has_avx2()) {
      unsigned blocked = 0;
      for (int half = 0; half < 2; ++half)
        blocked |= run_occlusion_packet(half_packet(rays, half), active + 4 * half, test, kernel)
                   << (4 * half);
      return blocked;
    }
  }
  if (test == TriangleTest::watertight)
    return kernel(rays, active, TestTag<TriangleTest::watertight>{});
  return kernel(rays, active, TestTag<TriangleTest::moller_trumbore>{});
}

} // namespace specula::accel
