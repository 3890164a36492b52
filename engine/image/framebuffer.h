#pragma once
/// \file
/// Framebuffer: a width × height grid of linear RGB radiance, the image type every renderer
/// writes and every metric and image file reader or writer takes.

#include "specula/core/math.h"

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace specula {

/// Largest framebuffer side. Equal to kMaxImageSide (scene/scene.h), repeated here so the image
/// module does not depend on scenes: a larger side is an absurd request, not an allocation.
inline constexpr std::uint32_t kMaxFramebufferSide = 16384;

/// Linear (scene-referred) RGB, row-major, row 0 at the top (the order of PNG and EXR scan lines
/// with increasing y). Values are unbounded floats; writers decide how to encode them.
class Framebuffer {
public:
  /// Throws specula::Error when a side is 0 or larger than kMaxFramebufferSide.
  Framebuffer(std::uint32_t width, std::uint32_t height, vec3 fill = vec3(0.0f));

  [[nodiscard]] std::uint32_t width() const noexcept { return width_; }
  [[nodiscard]] std::uint32_t height() const noexcept { return height_; }
  [[nodiscard]] std::size_t pixel_count() const noexcept { return pixels_.size(); }

  /// Pixel (x, y); out-of-range coordinates are a bug (SPECULA_ASSERT).
  [[nodiscard]] vec3& at(std::uint32_t x, std::uint32_t y);
  [[nodiscard]] const vec3& at(std::uint32_t x, std::uint32_t y) const;

  /// Every pixel, row-major (index y * width + x).
  [[nodiscard]] std::span<vec3> pixels() noexcept { return pixels_; }
  [[nodiscard]] std::span<const vec3> pixels() const noexcept { return pixels_; }

  void fill(vec3 value);

  /// Same size and bit-identical pixels (+0 and -0 compare equal, NaN never does).
  friend bool operator==(const Framebuffer& a, const Framebuffer& b) = default;

private:
  std::uint32_t width_;
  std::uint32_t height_;
  std::vector<vec3> pixels_;
};

/// Nearest-neighbour resampling: the source index under destination index `i`'s centre when
/// `dst` samples span `src` ones, in integers (what presentation uses to scale a frame up).
[[nodiscard]] constexpr std::uint64_t nearest_source(std::uint64_t i, std::uint64_t dst,
                                                     std::uint64_t src) noexcept {
  return ((2 * i + 1) * src) / (2 * dst);
}

/// `image` resampled to width × height by nearest_source on each axis (no letterbox: the aspect
/// follows the new size).
[[nodiscard]] Framebuffer resample_nearest(const Framebuffer& image, std::uint32_t width,
                                           std::uint32_t height);

/// Linear resampling on one axis: destination index i's centre falls between source samples
/// `lo` and `hi` (equal at the borders, which clamp), `weight` of the way to `hi`.
struct LinearTaps {
  std::uint32_t lo = 0, hi = 0;
  float weight = 0.0f;
};
[[nodiscard]] LinearTaps linear_source(std::uint64_t i, std::uint64_t dst, std::uint64_t src);

/// a + (b - a)·w with w = 0 giving a exactly (whatever b holds).
[[nodiscard]] inline vec3 lerp_taps(const vec3& a, const vec3& b, float w) {
  return w == 0.0f ? a : (1.0f - w) * a + w * b;
}

/// `image` resampled to width × height by linear_source on each axis (bilinear, in linear
/// colour; the same size gives the image back bit for bit).
[[nodiscard]] Framebuffer resample_bilinear(const Framebuffer& image, std::uint32_t width,
                                            std::uint32_t height);

} // namespace specula
