#include "specula/image/framebuffer.h"

#include "specula/core/assert.h"
#include "specula/core/error.h"

#include <algorithm>
#include <string>

namespace specula {

namespace {

std::uint32_t checked_side(std::uint32_t side, const char* name) {
  if (side == 0 || side > kMaxFramebufferSide) {
    throw Error(std::string("framebuffer ") + name + " " + std::to_string(side) +
                " is outside [1, " + std::to_string(kMaxFramebufferSide) + "]");
  }
  return side;
}

} // namespace

Framebuffer::Framebuffer(std::uint32_t width, std::uint32_t height, vec3 fill)
    : width_(checked_side(width, "width")), height_(checked_side(height, "height")),
      pixels_(std::size_t{width} * height, fill) {}

vec3& Framebuffer::at(std::uint32_t x, std::uint32_t y) {
  SPECULA_ASSERT(x < width_ && y < height_);
  return pixels_[std::size_t{y} * width_ + x];
}

const vec3& Framebuffer::at(std::uint32_t x, std::uint32_t y) const {
  SPECULA_ASSERT(x < width_ && y < height_);
  return pixels_[std::size_t{y} * width_ + x];
}

void Framebuffer::fill(vec3 value) { std::fill(pixels_.begin(), pixels_.end(), value); }

Framebuffer resample_nearest(const Framebuffer& image, std::uint32_t width, std::uint32_t height) {
  Framebuffer out(width, height);
  for (std::uint32_t y = 0; y < height; ++y) {
    const auto sy = std::uint32_t(nearest_source(y, height, image.height()));
    for (std::uint32_t x = 0; x < width; ++x)
      out.at(x, y) = image.at(std::uint32_t(nearest_source(x, width, image.width())), sy);
  }
  return out;
}

LinearTaps linear_source(std::uint64_t i, std::uint64_t dst, std::uint64_t src) {
  LinearTaps t;
  if (src == 0 || dst == 0) return t;
  // The centre of destination sample i, in source samples: (i + ½)·src/dst − ½ (exact in
  // double for any image size; i itself when src == dst).
  const double x = std::clamp((double(i) + 0.5) * double(src) / double(dst) - 0.5, 0.0,
                              double(src - 1));
  t.lo = std::uint32_t(x);
  t.hi = std::min(t.lo + 1, std::uint32_t(src - 1));
  t.weight = float(x - double(t.lo));
  return t;
}

Framebuffer resample_bilinear(const Framebuffer& image, std::uint32_t width,
                              std::uint32_t height) {
  Framebuffer out(width, height);
  for (std::uint32_t y = 0; y < height; ++y) {
    const LinearTaps ty = linear_source(y, height, image.height());
    for (std::uint32_t x = 0; x < width; ++x) {
      const LinearTaps tx = linear_source(x, width, image.width());
      out.at(x, y) =
          lerp_taps(lerp_taps(image.at(tx.lo, ty.lo), image.at(tx.hi, ty.lo), tx.weight),
                    lerp_taps(image.at(tx.lo, ty.hi), image.at(tx.hi, ty.hi), tx.weight),
                    ty.weight);
    }
  }
  return out;
}

} // namespace specula
