#pragma once
/// \file
/// SIMD lanes for the packet kernels of the kd-tree and the BVH: a small set of vector operations
/// for SSE (4 lanes, baseline x86-64) and for AVX2 (8 lanes, in functions with the avx2 target
/// attribute, chosen at run time), and the watertight triangle test over a packet's lanes written
/// once over them (packet_watertight.inl, included once per width). A kernel written over the
/// same operations is compiled twice the same way: inside a namespace that uses simd_sse or
/// simd_avx2, with SPECULA_SIMD_TARGET defined to match.

#include "specula/accel/common/ray_query.h"

#include <immintrin.h>

#include <bit>
#include <cstdint>
#include <type_traits>

namespace specula::accel {

/// One leaf's triangles against one lane of a packet, out of line and compiled for the baseline
/// target, so that its bits are those of the single-ray path whatever the kernel's target.
template <TriangleTest Test>
[[gnu::noinline]] inline void intersect_leaf(PreparedRay& r, const TriangleView& tris,
                                             const std::uint32_t* ids, std::uint32_t count,
                                             TriangleHit& hit) {
  for (std::uint32_t k = 0; k < count; ++k) intersect_closest<Test>(r, tris, ids[k], hit);
}

namespace simd_sse {
constexpr int kLanes = 4;
using Vf = __m128;
#define SPECULA_SIMD_TARGET
inline Vf vset1(float x) { return _mm_set1_ps(x); }
inline Vf vload(const float* p) { return _mm_load_ps(p); }
inline Vf vsub(Vf a, Vf b) { return _mm_sub_ps(a, b); }
inline Vf vmul(Vf a, Vf b) { return _mm_mul_ps(a, b); }
inline Vf vmin(Vf a, Vf b) { return _mm_min_ps(a, b); } // b where either is NaN
inline Vf vmax(Vf a, Vf b) { return _mm_max_ps(a, b); } // b where either is NaN
inline Vf vge(Vf a, Vf b) { return _mm_cmpge_ps(a, b); }
inline Vf vle(Vf a, Vf b) { return _mm_cmple_ps(a, b); }
inline Vf vlt(Vf a, Vf b) { return _mm_cmplt_ps(a, b); }
inline Vf vnan(Vf a) { return _mm_cmpunord_ps(a, a); }
inline Vf vor(Vf a, Vf b) { return _mm_or_ps(a, b); }
inline unsigned vmask(Vf a) { return unsigned(_mm_movemask_ps(a)); }
inline Vf vadd(Vf a, Vf b) { return _mm_add_ps(a, b); }
inline Vf vdiv(Vf a, Vf b) { return _mm_div_ps(a, b); }
inline Vf vgt(Vf a, Vf b) { return _mm_cmpgt_ps(a, b); }
inline Vf veq(Vf a, Vf b) { return _mm_cmpeq_ps(a, b); }
inline Vf vand(Vf a, Vf b) { return _mm_and_ps(a, b); }
inline Vf vxor(Vf a, Vf b) { return _mm_xor_ps(a, b); }
inline Vf vzero() { return _mm_setzero_ps(); }
inline void vstore(float* p, Vf a) { _mm_store_ps(p, a); }
/// Every lane set where its bit in `bits` is (lane i: bit i).
inline Vf vlanes(unsigned bits) {
  const __m128i bit = _mm_setr_epi32(1, 2, 4, 8);
  return _mm_castsi128_ps(_mm_cmpeq_epi32(_mm_and_si128(_mm_set1_epi32(int(bits)), bit), bit));
}
/// b where `mask` is set, else a.
inline Vf vselect(Vf a, Vf b, Vf mask) {
  return _mm_or_ps(_mm_and_ps(mask, b), _mm_andnot_ps(mask, a));
}
/// The least lane (no NaN among them).
inline float vhmin(Vf a) {
  a = _mm_min_ps(a, _mm_shuffle_ps(a, a, _MM_SHUFFLE(1, 0, 3, 2)));
  a = _mm_min_ps(a, _mm_shuffle_ps(a, a, _MM_SHUFFLE(2, 3, 0, 1)));
  return _mm_cvtss_f32(a);
}
/// The greatest lane (no NaN among them).
inline float vhmax(Vf a) {
  a = _mm_max_ps(a, _mm_shuffle_ps(a, a, _MM_SHUFFLE(1, 0, 3, 2)));
  a = _mm_max_ps(a, _mm_shuffle_ps(a, a, _MM_SHUFFLE(2, 3, 0, 1)));
  return _mm_cvtss_f32(a);
}
#include "packet_watertight.inl"
#undef SPECULA_SIMD_TARGET
} // namespace simd_sse

namespace simd_avx2 {
constexpr int kLanes = 8;
using Vf = __m256;
// AVX2 without FMA: GCC contracts a·b + c into an FMA even in ISO C++ mode, which would round the
// watertight test differently from the scalar path (and from lane to lane of a shared edge); the
// kernels have no use for FMA.
#define SPECULA_SIMD_TARGET __attribute__((target("avx2")))
SPECULA_SIMD_TARGET inline Vf vset1(float x) { return _mm256_set1_ps(x); }
SPECULA_SIMD_TARGET inline Vf vload(const float* p) { return _mm256_load_ps(p); }
SPECULA_SIMD_TARGET inline Vf vsub(Vf a, Vf b) { return _mm256_sub_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vmul(Vf a, Vf b) { return _mm256_mul_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vmin(Vf a, Vf b) { return _mm256_min_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vmax(Vf a, Vf b) { return _mm256_max_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vge(Vf a, Vf b) { return _mm256_cmp_ps(a, b, _CMP_GE_OQ); }
SPECULA_SIMD_TARGET inline Vf vle(Vf a, Vf b) { return _mm256_cmp_ps(a, b, _CMP_LE_OQ); }
SPECULA_SIMD_TARGET inline Vf vlt(Vf a, Vf b) { return _mm256_cmp_ps(a, b, _CMP_LT_OQ); }
SPECULA_SIMD_TARGET inline Vf vnan(Vf a) { return _mm256_cmp_ps(a, a, _CMP_UNORD_Q); }
SPECULA_SIMD_TARGET inline Vf vor(Vf a, Vf b) { return _mm256_or_ps(a, b); }
SPECULA_SIMD_TARGET inline unsigned vmask(Vf a) { return unsigned(_mm256_movemask_ps(a)); }
SPECULA_SIMD_TARGET inline Vf vadd(Vf a, Vf b) { return _mm256_add_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vdiv(Vf a, Vf b) { return _mm256_div_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vgt(Vf a, Vf b) { return _mm256_cmp_ps(a, b, _CMP_GT_OQ); }
SPECULA_SIMD_TARGET inline Vf veq(Vf a, Vf b) { return _mm256_cmp_ps(a, b, _CMP_EQ_OQ); }
SPECULA_SIMD_TARGET inline Vf vand(Vf a, Vf b) { return _mm256_and_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vxor(Vf a, Vf b) { return _mm256_xor_ps(a, b); }
SPECULA_SIMD_TARGET inline Vf vzero() { return _mm256_setzero_ps(); }
SPECULA_SIMD_TARGET inline void vstore(float* p, Vf a) { _mm256_store_ps(p, a); }
SPECULA_SIMD_TARGET inline Vf vlanes(unsigned bits) {
  const __m256i bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
  return _mm256_castsi256_ps(
      _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(int(bits)), bit), bit));
}
SPECULA_SIMD_TARGET inline Vf vselect(Vf a, Vf b, Vf mask) { return _mm256_blendv_ps(a, b, mask); }
SPECULA_SIMD_TARGET inline float vhmin(Vf a) {
  a = _mm256_min_ps(a, _mm256_permute2f128_ps(a, a, 1));
  a = _mm256_min_ps(a, _mm256_shuffle_ps(a, a, _MM_SHUFFLE(1, 0, 3, 2)));
  a = _mm256_min_ps(a, _mm256_shuffle_ps(a, a, _MM_SHUFFLE(2, 3, 0, 1)));
  return _mm256_cvtss_f32(a);
}
SPECULA_SIMD_TARGET inline float vhmax(Vf a) {
  a = _mm256_max_ps(a, _mm256_permute2f128_ps(a, a, 1));
  a = _mm256_max_ps(a, _mm256_shuffle_ps(a, a, _MM_SHUFFLE(1, 0, 3, 2)));
  a = _mm256_max_ps(a, _mm256_shuffle_ps(a, a, _MM_SHUFFLE(2, 3, 0, 1)));
  return _mm256_cvtss_f32(a);
}
#include "packet_watertight.inl"
#undef SPECULA_SIMD_TARGET
} // namespace simd_avx2

/// The lanes of a packet of N (4: SSE, 8: AVX2).
template <int N>
using WatertightLanesOf =
    std::conditional_t<N == 8, simd_avx2::WatertightLanes, simd_sse::WatertightLanes>;

/// prepare_coherent_lanes of the packet's width.
template <int N>
bool prepare_coherent_lanes(const RayPacket<N>& rays, const bool* active, const Aabb* box,
                            PreparedRay* out, float* tmin, float* tmax, unsigned& mask,
                            std::uint32_t neg[3], WatertightLanesOf<N>& w) {
  if constexpr (N == 8)
    return simd_avx2::prepare_coherent_lanes(rays, active, box, out, tmin, tmax, mask, neg, w);
  else
    return simd_sse::prepare_coherent_lanes(rays, active, box, out, tmin, tmax, mask, neg, w);
}

} // namespace specula::accel
