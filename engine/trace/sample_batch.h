#pragma once
/// \file
/// Sample dimensions of many samples at once (internal to the renderer): one set of each of many
/// (stream, index) pairs, as PixelSampler::set(…).dim(…) gives them, eight at a time with AVX2
/// where the CPU has it. A path tracer's wave draws its vertices' samples this way before it
/// shades them; the bits are the scalar sampler's (the same integer operations).

#include <cstddef>
#include <cstdint>
#include <span>

namespace specula::detail {

/// Strided views of the samples to draw: sample i is index `indices[i · stride]` of the stream
/// whose PixelSampler::stream_seed() is `seeds[i · stride]` (strides in 32-bit words, so that
/// the two can be fields of an array of structures).
struct SampleKeys {
  const std::uint32_t* seeds = nullptr;
  const std::uint32_t* indices = nullptr;
  std::size_t stride = 1;
  std::size_t count = 0;
};

/// Dimensions of one set of every sample: bit d of `dims` (d < 4) asks for dimension d, written
/// to out[i · out_stride + d] for sample i.
struct SampleRequest {
  std::uint32_t set = 0;
  std::uint32_t dims = 0;
  float* out = nullptr;
};

/// For every sample i of `keys` and every request r, every dimension d that r asks for:
/// r.out[i · out_stride + d] = PixelSampler::from_stream_seed(seed).set(index, r.set).dim(d).
/// `simd` false: one sample at a time (the tests compare the two).
void draw_sample_dims(const SampleKeys& keys, std::span<const SampleRequest> requests,
                      std::size_t out_stride, bool simd = true);

/// Whether draw_sample_dims(…, simd = true) runs the AVX2 code on this CPU.
[[nodiscard]] bool sample_dims_vectorised();

} // namespace specula::detail
