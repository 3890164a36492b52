// Sample dimensions of many samples at once (sample_batch.h): PixelSampler::set and
// SampleSet::dim, eight samples at a time with AVX2, one at a time otherwise.

#include "specula/trace/sample_batch.h"

#include "specula/trace/sampler.h"
#include "specula/trace/sampler_avx2.h"

namespace specula::detail {
namespace {

void one_sample(const SampleKeys& keys, std::size_t i, std::span<const SampleRequest> requests,
                std::size_t out_stride) {
  const PixelSampler sampler = PixelSampler::from_stream_seed(keys.seeds[i * keys.stride]);
  for (const SampleRequest& r : requests) {
    const SampleSet s = sampler.set(keys.indices[i * keys.stride], r.set);
    for (std::uint32_t d = 0; d < 4; ++d)
      if ((r.dims >> d & 1u) != 0) r.out[i * out_stride + d] = s.dim(d);
  }
}

/// Samples i0 … i0 + 7.
SPECULA_AVX2 void eight_samples(const SampleKeys& keys, std::size_t i0,
                                std::span<const SampleRequest> requests, std::size_t out_stride) {
  const __m256i lanes = _mm256_mullo_epi32(_mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
                                           _mm256_set1_epi32(int(keys.stride)));
  const std::size_t first = i0 * keys.stride;
  const __m256i seed =
      _mm256_i32gather_epi32(reinterpret_cast<const int*>(keys.seeds + first), lanes, 4);
  const __m256i reversed_index = reverse_bits8(
      _mm256_i32gather_epi32(reinterpret_cast<const int*>(keys.indices + first), lanes, 4));
  alignas(32) float values[8];
  for (const SampleRequest& r : requests) {
    // PixelSampler::set: the set's seed, then the shuffled index (owen_scramble).
    const __m256i set_seed = hash_combine8(seed, r.set);
    const __m256i shuffled = scramble_reversed8(reversed_index, set_seed);
    for (std::uint32_t d = 0; d < 4; ++d) {
      if ((r.dims >> d & 1u) == 0) continue;
      // SampleSet::dim.
      _mm256_store_ps(values, unit8(scramble_reversed8(sobol_reversed8(shuffled, d),
                                                       hash_combine8(set_seed, d + 1))));
      for (std::size_t lane = 0; lane < 8; ++lane)
        r.out[(i0 + lane) * out_stride + d] = values[lane];
    }
  }
}

} // namespace

bool sample_dims_vectorised() {
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
}

void draw_sample_dims(const SampleKeys& keys, std::span<const SampleRequest> requests,
                      std::size_t out_stride, bool simd) {
  std::size_t i = 0;
  // The gathers index the keys with 32-bit offsets.
  if (simd && sample_dims_vectorised() && keys.stride <= 0x0FFFFFFFu)
    for (; i + 8 <= keys.count; i += 8) eight_samples(keys, i, requests, out_stride);
  for (; i < keys.count; ++i) one_sample(keys, i, requests, out_stride);
}

} // namespace specula::detail
