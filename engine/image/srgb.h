#pragma once
/// \file
/// The sRGB transfer functions (IEC 61966-2-1), exact piecewise form, shared by the PNG reader
/// and writer and by the metrics that work on display-encoded values; and their 8-bit encoding,
/// shared by the PNG writer and presentation.

#include <array>
#include <bit>
#include <cmath>
#include <cstdint>

namespace specula {

/// Clamps to [0, 1] and maps NaN to 0, so that a bad value never reaches a cast to an integer.
[[nodiscard]] inline float clamp_unit(float v) noexcept {
  return v > 0.0f ? (v < 1.0f ? v : 1.0f) : 0.0f; // NaN fails `v > 0`: it becomes 0
}

/// sRGB OETF: linear [0, 1] → encoded [0, 1]. The linear toe below 0.0031308 avoids the infinite
/// slope of the power law at 0 (IEC 61966-2-1, eq. for V').
[[nodiscard]] inline float linear_to_srgb(float linear) noexcept {
  const float v = clamp_unit(linear);
  return v <= 0.0031308f ? 12.92f * v : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
}

/// sRGB EOTF: encoded [0, 1] → linear [0, 1]; the inverse of linear_to_srgb on [0, 1].
[[nodiscard]] inline float srgb_to_linear(float encoded) noexcept {
  const float v = clamp_unit(encoded);
  return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f);
}

/// Linear → 8-bit sRGB by definition: linear_to_srgb, then rounded to the nearest of 256 codes.
/// encode_srgb8 gives the same byte for every float without the pow (Srgb8Encoder).
[[nodiscard]] inline std::uint8_t encode_srgb8_reference(float linear) noexcept {
  // Round to nearest: the encoded value is in [0, 1], so +0.5 and truncation is exact rounding.
  return static_cast<std::uint8_t>(linear_to_srgb(linear) * 255.0f + 0.5f);
}

/// encode_srgb8_reference by table lookup, to the bit (a pow per channel was most of presenting a
/// frame and of writing a PNG). Over [0, 1] the reference is a step function of 255 steps; the
/// encoder holds where each step starts (threshold k: the least float that encodes to k, found by
/// bisection over the floats with the reference itself), and for each run of floats sharing their
/// top 16 bits (sign, exponent, 7 mantissa bits: a relative width of 1/128) the code at its first
/// float. No run holds more than one step (the curve rises by at most 0.9 codes over one: 255 ·
/// 1.055/2.4 · v^(1/2.4) per unit of ln v, and far less on the linear toe), so a lookup and one
/// comparison give the code. tests/image/test_framebuffer.cpp checks it against the reference on
/// every float of [0, 1] and on what the clamp sends there.
class Srgb8Encoder {
public:
  /// The tables, built on first use (thread-safe; about 2 ms).
  [[nodiscard]] static const Srgb8Encoder& get();

  [[nodiscard]] std::uint8_t operator()(float linear) const noexcept {
    const float v = clamp_unit(linear); // +0 for NaN, negatives and -0: every index is in range
    std::uint32_t k = run_code_[std::bit_cast<std::uint32_t>(v) >> kRunShift];
    k += v >= threshold_[k + 1] ? 1u : 0u;
    return static_cast<std::uint8_t>(k);
  }

  /// The least float of [0, 1] that encodes to k (k in 1..255).
  [[nodiscard]] float threshold(std::uint32_t k) const { return threshold_[k]; }

  static constexpr std::uint32_t kRunShift = 16;
  /// Runs over [0, 1]: the bit patterns of +0 … 1.0f, 16 bits dropped.
  static constexpr std::uint32_t kRuns = (0x3f800000u >> kRunShift) + 1;

private:
  Srgb8Encoder();
  std::array<std::uint8_t, kRuns> run_code_{};
  /// threshold_[0] = 0; threshold_[256] = 2, above every clamped value.
  std::array<float, 257> threshold_{};
};

/// Linear → 8-bit sRGB, as PNGs are written and frames presented (present/), so the two agree:
/// encode_srgb8_reference's byte. In a loop, hold Srgb8Encoder::get() once instead.
[[nodiscard]] inline std::uint8_t encode_srgb8(float linear) noexcept {
  return Srgb8Encoder::get()(linear);
}

} // namespace specula
