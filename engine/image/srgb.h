#pragma once
/// \file
/// The sRGB transfer functions (IEC 61966-2-1), exact piecewise form, shared by the PNG reader
/// and writer and by the metrics that work on display-encoded values.

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

/// Linear → 8-bit sRGB, as PNGs are written and frames presented (present/), so the two agree.
[[nodiscard]] inline std::uint8_t encode_srgb8(float linear) noexcept {
  // Round to nearest: the encoded value is in [0, 1], so +0.5 and truncation is exact rounding.
  return static_cast<std::uint8_t>(linear_to_srgb(linear) * 255.0f + 0.5f);
}

} // namespace specula
