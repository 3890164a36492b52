// The shadow caster's area-light samples (shadow_samples.h): one surface at a time, and eight at
// a time with AVX2. The vector code repeats the scalar code's operations in its order — the
// sampler's integer hashes, the branch-free pick, sample_emitter_triangle's arithmetic, the
// integrator's tests — with gathers for the table lookups and masks for the early returns, so the
// two give the same bits (tests/trace/test_shadow.cpp compares them, and the device test compares
// the result with the shader's).

#include "specula/trace/shadow_samples.h"

#include "specula/trace/area_lights.h"
#include "specula/trace/lanes_avx2.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <immintrin.h>

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

using avx2::dot;
using avx2::mul;
using avx2::TableInMemory;
using avx2::TableInRegisters;
using avx2::V3;

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

SPECULA_AVX2 inline __m256 load8(const std::vector<float>& v, std::size_t n0) {
  return _mm256_loadu_ps(v.data() + n0);
}

SPECULA_AVX2 inline __m256i load8(const std::vector<std::uint32_t>& v, std::size_t n0) {
  return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(v.data() + n0));
}

SPECULA_AVX2 inline avx2::V3 load8(const std::vector<float>& x, const std::vector<float>& y,
                                   const std::vector<float>& z, std::size_t n0) {
  return {load8(x, n0), load8(y, n0), load8(z, n0)};
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

  // sample_emitter_triangle, then the integrator's tests: in front of the surface, lit side of
  // the shading normal.
  const avx2::EmitterSample8 ls =
      avx2::emitter_sample8(table, k, load8(s.ox, s.oy, s.oz, n0), reused, u1);
  const V3& t = ls.to_light;
  __m256 ok = ls.ok;
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(dot(t, load8(s.gx, s.gy, s.gz, n0)), zero, _CMP_NLE_UQ));
  const __m256 cos_theta = dot(t, load8(s.sx, s.sy, s.sz, n0));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(cos_theta, zero, _CMP_NLE_UQ));

  const __m256 w = mul(_mm256_div_ps(cos_theta, ls.pdf), _mm256_set1_ps(inv_samples));
  const V3 emission = avx2::field3(table, k, offsetof(EmitterTriangle, emission));
  _mm256_storeu_ps(out.dx.data() + n0, t.x);
  _mm256_storeu_ps(out.dy.data() + n0, t.y);
  _mm256_storeu_ps(out.dz.data() + n0, t.z);
  _mm256_storeu_ps(out.tfar.data() + n0, mul(ls.distance, _mm256_set1_ps(1.0f - 1e-5f)));
  _mm256_storeu_ps(out.vr.data() + n0, mul(mul(load8(s.ar, n0), emission.x), w));
  _mm256_storeu_ps(out.vg.data() + n0, mul(mul(load8(s.ag, n0), emission.y), w));
  _mm256_storeu_ps(out.vb.data() + n0, mul(mul(load8(s.ab, n0), emission.z), w));
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
    const TableInMemory table(triangles);
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
  if (simd && shadow_light_rays_vectorised() &&
      table.triangles().size() <= avx2::kMostEmitterTriangles)
    first = eight_at_a_time(table, surfaces, index, inv_samples, out);
  for (; first < n; ++first) one_ray(table, surfaces, first, index, inv_samples, out);
}

} // namespace specula::detail
