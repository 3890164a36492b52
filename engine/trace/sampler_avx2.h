#pragma once
/// \file
/// The sampler's integer maths (sampler.h) eight lanes at a time with AVX2, internal to the
/// renderer: every function gives, lane by lane, the bits of its scalar namesake. Callers compile
/// them into functions marked SPECULA_AVX2 and run those only where the CPU has AVX2
/// (__builtin_cpu_supports).

#include "specula/trace/sampler.h"

#include <cstdint>
#include <immintrin.h>

#define SPECULA_AVX2 __attribute__((target("avx2")))

namespace specula::detail {

SPECULA_AVX2 inline __m256i reverse_bits8(__m256i x) {
  const __m256i bswap = _mm256_setr_epi8(3, 2, 1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12, 3, 2,
                                         1, 0, 7, 6, 5, 4, 11, 10, 9, 8, 15, 14, 13, 12);
  const __m256i m4 = _mm256_set1_epi32(0x0F0F0F0F);
  const __m256i m2 = _mm256_set1_epi32(0x33333333);
  const __m256i m1 = _mm256_set1_epi32(0x55555555);
  x = _mm256_shuffle_epi8(x, bswap);
  x = _mm256_or_si256(_mm256_and_si256(_mm256_srli_epi32(x, 4), m4),
                      _mm256_slli_epi32(_mm256_and_si256(x, m4), 4));
  x = _mm256_or_si256(_mm256_and_si256(_mm256_srli_epi32(x, 2), m2),
                      _mm256_slli_epi32(_mm256_and_si256(x, m2), 2));
  return _mm256_or_si256(_mm256_and_si256(_mm256_srli_epi32(x, 1), m1),
                         _mm256_slli_epi32(_mm256_and_si256(x, m1), 1));
}

/// sobol_detail::owen_scramble_reversed, lane by lane.
SPECULA_AVX2 inline __m256i times(__m256i a, std::uint32_t c) {
  return _mm256_mullo_epi32(a, _mm256_set1_epi32(int(c)));
}

SPECULA_AVX2 inline __m256i scramble_reversed8(__m256i rx, __m256i seed) {
  rx = _mm256_xor_si256(rx, times(rx, 0x3d20adeau));
  rx = _mm256_add_epi32(rx, seed);
  rx = _mm256_mullo_epi32(rx, _mm256_or_si256(_mm256_srli_epi32(seed, 16), _mm256_set1_epi32(1)));
  rx = _mm256_xor_si256(rx, times(rx, 0x05526c56u));
  rx = _mm256_xor_si256(rx, times(rx, 0x53a22864u));
  return reverse_bits8(rx);
}

/// sobol_reversed_u32, lane by lane.
SPECULA_AVX2 inline __m256i lookup(const std::array<std::uint32_t, 256>& table, __m256i byte) {
  return _mm256_i32gather_epi32(reinterpret_cast<const int*>(table.data()), byte, 4);
}

SPECULA_AVX2 inline __m256i sobol_reversed8(__m256i index, std::uint32_t d) {
  if (d == 0) return index; // van der Corput reversed
  const auto& t = sobol_detail::kReversedByteTables[d];
  const __m256i ff = _mm256_set1_epi32(0xFF);
  __m256i r = lookup(t[0], _mm256_and_si256(index, ff));
  r = _mm256_xor_si256(r, lookup(t[1], _mm256_and_si256(_mm256_srli_epi32(index, 8), ff)));
  r = _mm256_xor_si256(r, lookup(t[2], _mm256_and_si256(_mm256_srli_epi32(index, 16), ff)));
  return _mm256_xor_si256(r, lookup(t[3], _mm256_srli_epi32(index, 24)));
}

/// to_unit_float, lane by lane (x >> 8 < 2^24 converts exactly as a signed integer too).
SPECULA_AVX2 inline __m256 unit8(__m256i x) {
  return _mm256_mul_ps(_mm256_cvtepi32_ps(_mm256_srli_epi32(x, 8)),
                       _mm256_set1_ps(1.0f / 16777216.0f));
}

/// hash_u32, lane by lane.
SPECULA_AVX2 inline __m256i hash_u32_8(__m256i x) {
  x = _mm256_xor_si256(x, _mm256_srli_epi32(x, 16));
  x = times(x, 0x7feb352du);
  x = _mm256_xor_si256(x, _mm256_srli_epi32(x, 15));
  x = times(x, 0x846ca68bu);
  return _mm256_xor_si256(x, _mm256_srli_epi32(x, 16));
}

/// hash_combine(seed, v), lane by lane, for one v.
SPECULA_AVX2 inline __m256i hash_combine8(__m256i seed, std::uint32_t v) {
  const __m256i mixed = _mm256_add_epi32(
      _mm256_add_epi32(_mm256_set1_epi32(int(v + 0x9e3779b9u)), _mm256_slli_epi32(seed, 6)),
      _mm256_srli_epi32(seed, 2));
  return hash_u32_8(_mm256_xor_si256(seed, mixed));
}

} // namespace specula::detail
