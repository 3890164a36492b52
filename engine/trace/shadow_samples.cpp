// The shadow caster's area-light samples (shadow_samples.h): one surface at a time, and eight at
// a time with AVX2. The vector code repeats the scalar code's operations in its order — the
// sampler's integer hashes, the branch-free pick, sample_emitter_triangle's arithmetic, the
// integrator's tests — with gathers for the table lookups and masks for the early returns, so the
// two give the same bits (tests/trace/test_shadow.cpp compares them, and the device test compares
// the result with the shader's).

#include "specula/trace/shadow_samples.h"

#include "specula/trace/area_lights.h"
#include "specula/trace/sampler_avx2.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <immintrin.h>
#include <limits>
#include <type_traits>

namespace specula::detail {

void ShadowSurfaces::clear() {
  for (std::vector<float>* v : {&ox, &oy, &oz, &gx, &gy, &gz, &sx, &sy, &sz, &ar, &ag, &ab})
    v->clear();
  for (std::vector<std::uint32_t>* v : {&pixel, &set_seed, &seed0, &seed1}) v->clear();
}

void ShadowSurfaces::push(const vec3& origin, const vec3& geometric_normal,
                          const vec3& shading_normal, const vec3& albedo, std::uint32_t image_pixel,
                          const PixelSampler::Stream2& stream) {
  ox.push_back(origin.x);
  oy.push_back(origin.y);
  oz.push_back(origin.z);
  gx.push_back(geometric_normal.x);
  gy.push_back(geometric_normal.y);
  gz.push_back(geometric_normal.z);
  sx.push_back(shading_normal.x);
  sy.push_back(shading_normal.y);
  sz.push_back(shading_normal.z);
  ar.push_back(albedo.x);
  ag.push_back(albedo.y);
  ab.push_back(albedo.z);
  pixel.push_back(image_pixel);
  set_seed.push_back(stream.set_seed());
  seed0.push_back(stream.seed0());
  seed1.push_back(stream.seed1());
}

void ShadowLightRays::resize(std::size_t n) {
  valid.resize(n);
  for (std::vector<float>* v : {&dx, &dy, &dz, &tfar, &vr, &vg, &vb}) v->resize(n);
}

namespace {

static_assert(std::is_standard_layout_v<EmitterTriangle> &&
                  sizeof(EmitterTriangle) % sizeof(float) == 0,
              "the vector code gathers EmitterTriangle fields as floats");

/// A light point from one sample: dimension 0 picks the triangle and, rescaled to its interval of
/// the CDF, places the point along with dimension 1. Dimensions (0, 1) of a pixel's first 2^m
/// samples form a (0,m,2)-net, so the light points of a pixel are stratified over the CDF's order
/// of triangles and within them (docs/design/shadow-caster.md).
AreaLightSample area_light_point(const EmitterTable& table, const vec3& p, const vec2& u) {
  const std::uint32_t k = table.pick(u.x);
  const EmitterTriangle& e = table.triangles()[k];
  const float below = e.cdf - e.pick;
  const float reused = std::clamp((u.x - below) / e.pick, 0.0f, 0x1.fffffep-1f);
  return sample_emitter_triangle(table, k, p, reused, u.y);
}

/// Surface n's sample, one at a time.
void one_ray(const EmitterTable& table, const ShadowSurfaces& s, std::size_t n, std::uint32_t index,
             float inv_samples, ShadowLightRays& out) {
  out.valid[n] = 0;
  const vec2 u = PixelSampler::Stream2(s.set_seed[n], s.seed0[n], s.seed1[n]).get(index);
  // Sampled from the shadow ray's own origin, so that the sample's direction and distance are
  // the ray's (one normalisation, not two); the density is the solid angle there.
  const AreaLightSample ls = area_light_point(table, vec3(s.ox[n], s.oy[n], s.oz[n]), u);
  if (!(ls.pdf > 0.0f)) return;
  if (glm::dot(ls.to_light, vec3(s.gx[n], s.gy[n], s.gz[n])) <= 0.0f) return; // behind it
  const float cos_theta = glm::dot(ls.to_light, vec3(s.sx[n], s.sy[n], s.sz[n]));
  if (cos_theta <= 0.0f) return;
  const vec3 value =
      vec3(s.ar[n], s.ag[n], s.ab[n]) * ls.emission * (cos_theta / ls.pdf * inv_samples);
  out.valid[n] = 1;
  out.dx[n] = ls.to_light.x;
  out.dy[n] = ls.to_light.y;
  out.dz[n] = ls.to_light.z;
  // Aimed at the light point itself and stopped just short of it, so that the emitting
  // triangle never shadows its own sample.
  out.tfar[n] = ls.distance * (1.0f - 1e-5f);
  out.vr[n] = value.x;
  out.vg[n] = value.y;
  out.vb[n] = value.z;
}

SPECULA_AVX2 inline __m256 dot8(__m256 ax, __m256 ay, __m256 az, __m256 bx, __m256 by, __m256 bz) {
  // glm::dot of vec3: the products, then (x + y) + z.
  return _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(ax, bx), _mm256_mul_ps(ay, by)),
                       _mm256_mul_ps(az, bz));
}

SPECULA_AVX2 inline __m256 load8(const std::vector<float>& v, std::size_t n0) {
  return _mm256_loadu_ps(v.data() + n0);
}

SPECULA_AVX2 inline __m256i load8(const std::vector<std::uint32_t>& v, std::size_t n0) {
  return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(v.data() + n0));
}

constexpr int kStride = int(sizeof(EmitterTriangle) / sizeof(float));

/// The emitter table read from memory, any size: a triangle is its offset in floats (index ×
/// kStride), a field a gather, the pick EmitterTable::pick's branch-free search, a gather a step.
struct TableInMemory {
  const float* base;
  std::size_t count;

  SPECULA_AVX2 __m256 field(__m256i element, std::size_t offset) const {
    return _mm256_i32gather_ps(base + offset / sizeof(float), element, 4);
  }
  /// The picked triangles, and the mask of lanes whose u0 is at or above every cdf.
  SPECULA_AVX2 __m256i pick(__m256 u0, __m256i& past) const {
    const __m256i stride = _mm256_set1_epi32(kStride);
    __m256i first = _mm256_setzero_si256(); // in floats: triangle index × kStride
    std::size_t n = count;
    while (n > 1) {
      const std::size_t half = n / 2;
      const __m256i ahead = _mm256_add_epi32(first, _mm256_set1_epi32(int(half) * kStride));
      const __m256 below =
          _mm256_cmp_ps(u0, field(ahead, offsetof(EmitterTriangle, cdf)), _CMP_LT_OQ);
      first = _mm256_blendv_epi8(ahead, first, _mm256_castps_si256(below));
      n -= half;
    }
    const __m256 below =
        _mm256_cmp_ps(u0, field(first, offsetof(EmitterTriangle, cdf)), _CMP_LT_OQ);
    first = _mm256_blendv_epi8(_mm256_add_epi32(first, stride), first, _mm256_castps_si256(below));
    past = _mm256_cmpeq_epi32(first, _mm256_set1_epi32(int(count) * kStride));
    return first;
  }
};

/// A table of at most eight triangles held in registers: a triangle is its index, a field a
/// permute of the eight triangles' values, the pick a count of the cdfs at or below u0 — the
/// index the search finds, since the cdfs never decrease.
struct TableInRegisters {
  static constexpr std::size_t kMost = 8;
  __m256 fields[kStride];
  __m256 cdf[kMost]; ///< each triangle's cdf in every lane
  std::size_t count;

  SPECULA_AVX2 explicit TableInRegisters(const std::vector<EmitterTriangle>& triangles)
      : count(triangles.size()) {
    alignas(32) float column[kMost] = {};
    const auto* words = reinterpret_cast<const float*>(triangles.data());
    for (int f = 0; f < kStride; ++f) {
      for (std::size_t t = 0; t < kMost; ++t)
        column[t] = t < count ? words[t * std::size_t(kStride) + std::size_t(f)] : 0.0f;
      fields[f] = _mm256_load_ps(column);
    }
    for (std::size_t t = 0; t < count; ++t) cdf[t] = _mm256_set1_ps(triangles[t].cdf);
  }
  SPECULA_AVX2 __m256 field(__m256i index, std::size_t offset) const {
    return _mm256_permutevar8x32_ps(fields[offset / sizeof(float)], index);
  }
  SPECULA_AVX2 __m256i pick(__m256 u0, __m256i& past) const {
    __m256i k = _mm256_setzero_si256();
    for (std::size_t t = 0; t < count; ++t) // − (all ones) where !(u0 < cdf)
      k = _mm256_sub_epi32(k, _mm256_castps_si256(_mm256_cmp_ps(u0, cdf[t], _CMP_NLT_UQ)));
    past = _mm256_cmpeq_epi32(k, _mm256_set1_epi32(int(count)));
    return k;
  }
};

/// p0 + b1 · e1 + b2 · e2, one coordinate (the offsets of its p0, e1 and e2).
template <typename Table>
SPECULA_AVX2 inline __m256 point8(const Table& table, __m256i k, __m256 b1, __m256 b2,
                                  std::size_t p0, std::size_t e1, std::size_t e2) {
  return _mm256_add_ps(_mm256_add_ps(table.field(k, p0), _mm256_mul_ps(b1, table.field(k, e1))),
                       _mm256_mul_ps(b2, table.field(k, e2)));
}

/// Surfaces n0 … n0 + 7's samples.
template <typename Table>
SPECULA_AVX2 void eight_rays(const EmitterTable& emitters, const Table& table,
                             const ShadowSurfaces& s, std::size_t n0, std::uint32_t index,
                             float inv_samples, ShadowLightRays& out) {
  // PixelSampler::Stream2::get: the shuffled index, then dimensions 0 and 1.
  const __m256i shuffled = scramble_reversed8(
      _mm256_set1_epi32(int(sobol_detail::reverse_bits(index))), load8(s.set_seed, n0));
  const __m256 u0 = unit8(scramble_reversed8(sobol_reversed8(shuffled, 0), load8(s.seed0, n0)));
  const __m256 u1 = unit8(scramble_reversed8(sobol_reversed8(shuffled, 1), load8(s.seed1, n0)));

  // EmitterTable::pick's triangle; lanes at or above every cdf take the scalar code's fallback.
  __m256i past;
  const __m256i k = table.pick(u0, past);
  if (_mm256_movemask_epi8(past) != 0) {
    for (std::size_t n = n0; n < n0 + 8; ++n) one_ray(emitters, s, n, index, inv_samples, out);
    return;
  }
  const __m256 cdf = table.field(k, offsetof(EmitterTriangle, cdf));
  const __m256 pick = table.field(k, offsetof(EmitterTriangle, pick));
  // area_light_point: u0 reused within the picked interval, clamped as std::clamp does.
  const __m256 zero = _mm256_setzero_ps();
  const __m256 top = _mm256_set1_ps(0x1.fffffep-1f);
  const __m256 v = _mm256_div_ps(_mm256_sub_ps(u0, _mm256_sub_ps(cdf, pick)), pick);
  const __m256 low = _mm256_blendv_ps(v, zero, _mm256_cmp_ps(v, zero, _CMP_LT_OQ));
  const __m256 reused = _mm256_blendv_ps(low, top, _mm256_cmp_ps(top, low, _CMP_LT_OQ));

  // sample_emitter_triangle.
  const __m256 r = _mm256_sqrt_ps(reused);
  const __m256 b1 = _mm256_sub_ps(_mm256_set1_ps(1.0f), r);
  const __m256 b2 = _mm256_mul_ps(u1, r);
  constexpr std::size_t kP0 = offsetof(EmitterTriangle, p0);
  constexpr std::size_t kE1 = offsetof(EmitterTriangle, e1);
  constexpr std::size_t kE2 = offsetof(EmitterTriangle, e2);
  constexpr std::size_t kF = sizeof(float);
  const __m256 dx = _mm256_sub_ps(point8(table, k, b1, b2, kP0, kE1, kE2), load8(s.ox, n0));
  const __m256 dy =
      _mm256_sub_ps(point8(table, k, b1, b2, kP0 + kF, kE1 + kF, kE2 + kF), load8(s.oy, n0));
  const __m256 dz = _mm256_sub_ps(
      point8(table, k, b1, b2, kP0 + 2 * kF, kE1 + 2 * kF, kE2 + 2 * kF), load8(s.oz, n0));
  const __m256 dist = _mm256_sqrt_ps(dot8(dx, dy, dz, dx, dy, dz));
  const __m256 inf = _mm256_set1_ps(std::numeric_limits<float>::infinity());
  __m256 ok =
      _mm256_and_ps(_mm256_cmp_ps(dist, zero, _CMP_GT_OQ), _mm256_cmp_ps(dist, inf, _CMP_LT_OQ));
  const __m256 tx = _mm256_div_ps(dx, dist);
  const __m256 ty = _mm256_div_ps(dy, dist);
  const __m256 tz = _mm256_div_ps(dz, dist);
  constexpr std::size_t kN = offsetof(EmitterTriangle, normal);
  const __m256 cos_l =
      _mm256_andnot_ps(_mm256_set1_ps(-0.0f), dot8(table.field(k, kN), table.field(k, kN + kF),
                                                   table.field(k, kN + 2 * kF), tx, ty, tz));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(cos_l, zero, _CMP_GT_OQ));
  const __m256 area = table.field(k, offsetof(EmitterTriangle, area));
  const __m256 pdf =
      _mm256_div_ps(_mm256_mul_ps(_mm256_mul_ps(_mm256_div_ps(pick, area), dist), dist), cos_l);
  ok = _mm256_and_ps(
      ok, _mm256_and_ps(_mm256_cmp_ps(pdf, zero, _CMP_GT_OQ), _mm256_cmp_ps(pdf, inf, _CMP_LT_OQ)));

  // The integrator's tests: in front of the surface, lit side of the shading normal.
  const __m256 facing = dot8(tx, ty, tz, load8(s.gx, n0), load8(s.gy, n0), load8(s.gz, n0));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(facing, zero, _CMP_NLE_UQ));
  const __m256 cos_theta = dot8(tx, ty, tz, load8(s.sx, n0), load8(s.sy, n0), load8(s.sz, n0));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(cos_theta, zero, _CMP_NLE_UQ));

  const __m256 w = _mm256_mul_ps(_mm256_div_ps(cos_theta, pdf), _mm256_set1_ps(inv_samples));
  constexpr std::size_t kEm = offsetof(EmitterTriangle, emission);
  _mm256_storeu_ps(out.dx.data() + n0, tx);
  _mm256_storeu_ps(out.dy.data() + n0, ty);
  _mm256_storeu_ps(out.dz.data() + n0, tz);
  _mm256_storeu_ps(out.tfar.data() + n0, _mm256_mul_ps(dist, _mm256_set1_ps(1.0f - 1e-5f)));
  _mm256_storeu_ps(out.vr.data() + n0,
                   _mm256_mul_ps(_mm256_mul_ps(load8(s.ar, n0), table.field(k, kEm)), w));
  _mm256_storeu_ps(out.vg.data() + n0,
                   _mm256_mul_ps(_mm256_mul_ps(load8(s.ag, n0), table.field(k, kEm + kF)), w));
  _mm256_storeu_ps(out.vb.data() + n0,
                   _mm256_mul_ps(_mm256_mul_ps(load8(s.ab, n0), table.field(k, kEm + 2 * kF)), w));
  const int mask = _mm256_movemask_ps(ok);
  for (int lane = 0; lane < 8; ++lane) out.valid[n0 + std::size_t(lane)] = (mask >> lane) & 1;
}

/// The groups of eight surfaces; returns the first surface left to the scalar code.
SPECULA_AVX2 std::size_t eight_at_a_time(const EmitterTable& emitters, const ShadowSurfaces& s,
                                         std::uint32_t index, float inv_samples,
                                         ShadowLightRays& out) {
  const std::vector<EmitterTriangle>& triangles = emitters.triangles();
  std::size_t first = 0;
  if (triangles.size() <= TableInRegisters::kMost) {
    const TableInRegisters table(triangles);
    for (; first + 8 <= s.size(); first += 8)
      eight_rays(emitters, table, s, first, index, inv_samples, out);
  } else {
    const TableInMemory table{reinterpret_cast<const float*>(triangles.data()), triangles.size()};
    for (; first + 8 <= s.size(); first += 8)
      eight_rays(emitters, table, s, first, index, inv_samples, out);
  }
  return first;
}

} // namespace

bool shadow_light_rays_vectorised() {
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
}

void shadow_light_rays(const EmitterTable& table, const ShadowSurfaces& surfaces,
                       std::uint32_t index, float inv_samples, ShadowLightRays& out, bool simd) {
  const std::size_t n = surfaces.size();
  out.resize(n);
  if (table.empty()) {
    std::fill(out.valid.begin(), out.valid.end(), std::uint8_t{0});
    return;
  }
  std::size_t first = 0;
  // The gathers index the triangles' floats with 32-bit offsets.
  constexpr std::size_t kMostTriangles = std::size_t(std::numeric_limits<std::int32_t>::max()) /
                                             sizeof(EmitterTriangle) * sizeof(float) -
                                         1;
  if (simd && shadow_light_rays_vectorised() && table.triangles().size() <= kMostTriangles)
    first = eight_at_a_time(table, surfaces, index, inv_samples, out);
  for (; first < n; ++first) one_ray(table, surfaces, first, index, inv_samples, out);
}

} // namespace specula::detail
