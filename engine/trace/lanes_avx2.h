#pragma once
/// \file
/// Eight-lane float arithmetic with AVX2 for the renderer's batched code (internal): vectors as
/// three registers, glm's operations in glm's order (each correctly rounded, none fused), so a
/// lane gives the bits of the scalar code it repeats; gathers from the scene's tables; an 8 × 8
/// transpose; and the emitter table as eight lanes see it (in memory, or held in registers when it
/// has at most eight triangles). Callers compile them into functions marked SPECULA_AVX2 and run
/// those only where the CPU has AVX2.

#include "specula/core/math.h"
#include "specula/render/emitters.h"
#include "specula/trace/sampler_avx2.h"

#include <cstddef>
#include <immintrin.h>
#include <limits>
#include <type_traits>

namespace specula::detail::avx2 {

struct V3 {
  __m256 x, y, z;
};

SPECULA_AVX2 inline __m256 add(__m256 a, __m256 b) { return _mm256_add_ps(a, b); }
SPECULA_AVX2 inline __m256 sub(__m256 a, __m256 b) { return _mm256_sub_ps(a, b); }
SPECULA_AVX2 inline __m256 mul(__m256 a, __m256 b) { return _mm256_mul_ps(a, b); }
SPECULA_AVX2 inline __m256 neg(__m256 a) { return _mm256_xor_ps(a, _mm256_set1_ps(-0.0f)); }
SPECULA_AVX2 inline V3 scale(__m256 s, const V3& v) {
  return {mul(s, v.x), mul(s, v.y), mul(s, v.z)};
}
SPECULA_AVX2 inline V3 add(const V3& a, const V3& b) {
  return {add(a.x, b.x), add(a.y, b.y), add(a.z, b.z)};
}
SPECULA_AVX2 inline V3 sub(const V3& a, const V3& b) {
  return {sub(a.x, b.x), sub(a.y, b.y), sub(a.z, b.z)};
}
/// glm::dot: the products, then (x + y) + z.
SPECULA_AVX2 inline __m256 dot(const V3& a, const V3& b) {
  return add(add(mul(a.x, b.x), mul(a.y, b.y)), mul(a.z, b.z));
}
/// glm::cross.
SPECULA_AVX2 inline V3 cross(const V3& a, const V3& b) {
  return {sub(mul(a.y, b.z), mul(b.y, a.z)), sub(mul(a.z, b.x), mul(b.z, a.x)),
          sub(mul(a.x, b.y), mul(b.x, a.y))};
}
/// glm::abs (x >= 0 ? x : -x, so −0 stays −0).
SPECULA_AVX2 inline __m256 abs(__m256 x) {
  return _mm256_blendv_ps(neg(x), x, _mm256_cmp_ps(x, _mm256_setzero_ps(), _CMP_GE_OQ));
}
SPECULA_AVX2 inline V3 abs(const V3& v) { return {abs(v.x), abs(v.y), abs(v.z)}; }
/// glm::max and std::max: (x < y) ? y : x.
SPECULA_AVX2 inline __m256 max(__m256 x, __m256 y) { return _mm256_max_ps(y, x); }
SPECULA_AVX2 inline V3 max(const V3& a, const V3& b) {
  return {max(a.x, b.x), max(a.y, b.y), max(a.z, b.z)};
}
/// w·a + u·b + v·c, as glm evaluates it: (w·a + u·b) + v·c.
SPECULA_AVX2 inline V3 interpolate(__m256 w, __m256 u, __m256 v, const V3& a, const V3& b,
                                   const V3& c) {
  return add(add(scale(w, a), scale(u, b)), scale(v, c));
}
/// Lanes of `a` where `mask` is set, of `b` elsewhere.
SPECULA_AVX2 inline V3 select(__m256 mask, const V3& a, const V3& b) {
  return {_mm256_blendv_ps(b.x, a.x, mask), _mm256_blendv_ps(b.y, a.y, mask),
          _mm256_blendv_ps(b.z, a.z, mask)};
}

SPECULA_AVX2 inline __m256i gather_i(const void* base, __m256i index, __m256i mask) {
  return _mm256_mask_i32gather_epi32(_mm256_setzero_si256(), static_cast<const int*>(base), index,
                                     mask, 4);
}
SPECULA_AVX2 inline __m256 gather_f(const float* base, __m256i index, __m256i mask) {
  return _mm256_mask_i32gather_ps(_mm256_setzero_ps(), base, index, _mm256_castsi256_ps(mask), 4);
}
/// The three coordinates of vector `index` (in vec3 units) of a vec3 array.
SPECULA_AVX2 inline V3 gather3(const vec3* base, __m256i index, __m256i mask) {
  const float* f = &base->x;
  const __m256i i3 = _mm256_mullo_epi32(index, _mm256_set1_epi32(3));
  return {gather_f(f, i3, mask), gather_f(f + 1, i3, mask), gather_f(f + 2, i3, mask)};
}

/// Rows become columns: r[i][j] ← r[j][i].
SPECULA_AVX2 inline void transpose8(__m256 (&r)[8]) {
  const __m256 t0 = _mm256_unpacklo_ps(r[0], r[1]), t1 = _mm256_unpackhi_ps(r[0], r[1]);
  const __m256 t2 = _mm256_unpacklo_ps(r[2], r[3]), t3 = _mm256_unpackhi_ps(r[2], r[3]);
  const __m256 t4 = _mm256_unpacklo_ps(r[4], r[5]), t5 = _mm256_unpackhi_ps(r[4], r[5]);
  const __m256 t6 = _mm256_unpacklo_ps(r[6], r[7]), t7 = _mm256_unpackhi_ps(r[6], r[7]);
  const __m256 u0 = _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(1, 0, 1, 0));
  const __m256 u1 = _mm256_shuffle_ps(t0, t2, _MM_SHUFFLE(3, 2, 3, 2));
  const __m256 u2 = _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(1, 0, 1, 0));
  const __m256 u3 = _mm256_shuffle_ps(t1, t3, _MM_SHUFFLE(3, 2, 3, 2));
  const __m256 u4 = _mm256_shuffle_ps(t4, t6, _MM_SHUFFLE(1, 0, 1, 0));
  const __m256 u5 = _mm256_shuffle_ps(t4, t6, _MM_SHUFFLE(3, 2, 3, 2));
  const __m256 u6 = _mm256_shuffle_ps(t5, t7, _MM_SHUFFLE(1, 0, 1, 0));
  const __m256 u7 = _mm256_shuffle_ps(t5, t7, _MM_SHUFFLE(3, 2, 3, 2));
  r[0] = _mm256_permute2f128_ps(u0, u4, 0x20);
  r[1] = _mm256_permute2f128_ps(u1, u5, 0x20);
  r[2] = _mm256_permute2f128_ps(u2, u6, 0x20);
  r[3] = _mm256_permute2f128_ps(u3, u7, 0x20);
  r[4] = _mm256_permute2f128_ps(u0, u4, 0x31);
  r[5] = _mm256_permute2f128_ps(u1, u5, 0x31);
  r[6] = _mm256_permute2f128_ps(u2, u6, 0x31);
  r[7] = _mm256_permute2f128_ps(u3, u7, 0x31);
}

static_assert(std::is_standard_layout_v<EmitterTriangle> &&
                  sizeof(EmitterTriangle) % sizeof(float) == 0,
              "the vector code gathers EmitterTriangle fields as floats");

/// Words of an EmitterTriangle.
inline constexpr int kEmitterStride = int(sizeof(EmitterTriangle) / sizeof(float));

/// Most triangles an emitter table may have for the gathers' 32-bit word offsets.
inline constexpr std::size_t kMostEmitterTriangles =
    std::size_t(0x7fffffff) / sizeof(EmitterTriangle) * sizeof(float) - 1;

/// The emitter table read from memory, any size: a triangle is its offset in floats (index ×
/// kEmitterStride), a field a gather, the pick EmitterTable::pick's branch-free search, a gather a
/// step.
struct TableInMemory {
  const float* base;
  std::size_t count;

  explicit TableInMemory(const std::vector<EmitterTriangle>& triangles)
      : base(reinterpret_cast<const float*>(triangles.data())), count(triangles.size()) {}

  SPECULA_AVX2 __m256 field(__m256i element, std::size_t offset) const {
    return _mm256_i32gather_ps(base + offset / sizeof(float), element, 4);
  }
  /// The picked triangles, and the mask of lanes whose u0 is at or above every cdf.
  SPECULA_AVX2 __m256i pick(__m256 u0, __m256i& past) const {
    const __m256i stride = _mm256_set1_epi32(kEmitterStride);
    __m256i first = _mm256_setzero_si256(); // in floats: triangle index × kEmitterStride
    std::size_t n = count;
    while (n > 1) {
      const std::size_t half = n / 2;
      const __m256i ahead = _mm256_add_epi32(first, _mm256_set1_epi32(int(half) * kEmitterStride));
      const __m256 below =
          _mm256_cmp_ps(u0, field(ahead, offsetof(EmitterTriangle, cdf)), _CMP_LT_OQ);
      first = _mm256_blendv_epi8(ahead, first, _mm256_castps_si256(below));
      n -= half;
    }
    const __m256 below =
        _mm256_cmp_ps(u0, field(first, offsetof(EmitterTriangle, cdf)), _CMP_LT_OQ);
    first = _mm256_blendv_epi8(_mm256_add_epi32(first, stride), first, _mm256_castps_si256(below));
    past = _mm256_cmpeq_epi32(first, _mm256_set1_epi32(int(count) * kEmitterStride));
    return first;
  }
};

/// A table of at most eight triangles held in registers: a triangle is its index, a field a
/// permute of the eight triangles' values, the pick a count of the cdfs at or below u0 — the
/// index the search finds, since the cdfs never decrease.
struct TableInRegisters {
  static constexpr std::size_t kMost = 8;
  __m256 fields[kEmitterStride];
  __m256 cdf[kMost]; ///< each triangle's cdf in every lane
  std::size_t count;

  SPECULA_AVX2 explicit TableInRegisters(const std::vector<EmitterTriangle>& triangles)
      : count(triangles.size()) {
    alignas(32) float column[kMost] = {};
    const auto* words = reinterpret_cast<const float*>(triangles.data());
    for (int f = 0; f < kEmitterStride; ++f) {
      for (std::size_t t = 0; t < kMost; ++t)
        column[t] = t < count ? words[t * std::size_t(kEmitterStride) + std::size_t(f)] : 0.0f;
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

/// The three floats of a vec3 field of the picked triangles (its offset in bytes).
template <typename Table>
SPECULA_AVX2 inline V3 field3(const Table& table, __m256i k, std::size_t offset) {
  return {table.field(k, offset), table.field(k, offset + sizeof(float)),
          table.field(k, offset + 2 * sizeof(float))};
}

/// p0 + b1 · e1 + b2 · e2 on the picked triangles (sample_emitter_triangle's light point).
template <typename Table>
SPECULA_AVX2 inline V3 light_point(const Table& table, __m256i k, __m256 b1, __m256 b2) {
  return add(add(field3(table, k, offsetof(EmitterTriangle, p0)),
                 scale(b1, field3(table, k, offsetof(EmitterTriangle, e1)))),
             scale(b2, field3(table, k, offsetof(EmitterTriangle, e2))));
}

/// A light point's direction, distance and solid-angle density from eight points (as
/// sample_emitter_triangle computes them); `ok` where the sample is usable (a positive, finite
/// distance, cosine and density: where the scalar code leaves pdf > 0).
struct EmitterSample8 {
  V3 to_light;
  __m256 distance, pdf, ok;
};

/// sample_emitter_triangle on picked triangles `k` from points `p`, with the square-root map's
/// numbers (u1, u2).
template <typename Table>
SPECULA_AVX2 inline EmitterSample8 emitter_sample8(const Table& table, __m256i k, const V3& p,
                                                   __m256 u1, __m256 u2) {
  const __m256 r = _mm256_sqrt_ps(u1);
  const __m256 b1 = sub(_mm256_set1_ps(1.0f), r);
  const __m256 b2 = mul(u2, r);
  const V3 d = sub(light_point(table, k, b1, b2), p);
  EmitterSample8 s;
  s.distance = _mm256_sqrt_ps(dot(d, d));
  const __m256 zero = _mm256_setzero_ps();
  const __m256 inf = _mm256_set1_ps(std::numeric_limits<float>::infinity());
  s.ok = _mm256_and_ps(_mm256_cmp_ps(s.distance, zero, _CMP_GT_OQ),
                       _mm256_cmp_ps(s.distance, inf, _CMP_LT_OQ));
  s.to_light = {_mm256_div_ps(d.x, s.distance), _mm256_div_ps(d.y, s.distance),
                _mm256_div_ps(d.z, s.distance)};
  const __m256 cos_l = _mm256_andnot_ps(
      _mm256_set1_ps(-0.0f), dot(field3(table, k, offsetof(EmitterTriangle, normal)), s.to_light));
  s.ok = _mm256_and_ps(s.ok, _mm256_cmp_ps(cos_l, zero, _CMP_GT_OQ));
  const __m256 pick = table.field(k, offsetof(EmitterTriangle, pick));
  const __m256 area = table.field(k, offsetof(EmitterTriangle, area));
  s.pdf = _mm256_div_ps(mul(mul(_mm256_div_ps(pick, area), s.distance), s.distance), cos_l);
  s.ok = _mm256_and_ps(s.ok, _mm256_and_ps(_mm256_cmp_ps(s.pdf, zero, _CMP_GT_OQ),
                                           _mm256_cmp_ps(s.pdf, inf, _CMP_LT_OQ)));
  return s;
}

} // namespace specula::detail::avx2
