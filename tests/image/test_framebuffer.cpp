// Framebuffer: size validation, row-major layout, fill and equality.

#include "specula/core/error.h"
#include "specula/image/framebuffer.h"
#include "specula/image/srgb.h"

#include "sanitizers.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>

namespace specula {
namespace {

TEST(Framebuffer, HasRequestedSizeAndFill) {
  const Framebuffer image(7, 3, vec3(0.25f, 0.5f, 2.0f));
  EXPECT_EQ(image.width(), 7u);
  EXPECT_EQ(image.height(), 3u);
  EXPECT_EQ(image.pixel_count(), 21u);
  for (const vec3& p : image.pixels()) EXPECT_EQ(p, vec3(0.25f, 0.5f, 2.0f));
}

TEST(Framebuffer, RowMajorTopRowFirst) {
  Framebuffer image(4, 3);
  image.at(1, 2) = vec3(1.0f, 2.0f, 3.0f);
  EXPECT_EQ(image.pixels()[2 * 4 + 1], vec3(1.0f, 2.0f, 3.0f));
  image.fill(vec3(5.0f));
  EXPECT_EQ(image.at(1, 2), vec3(5.0f));
}

TEST(Framebuffer, RejectsZeroAndAbsurdSides) {
  EXPECT_THROW(Framebuffer(0, 10), Error);
  EXPECT_THROW(Framebuffer(10, 0), Error);
  EXPECT_THROW(Framebuffer(kMaxFramebufferSide + 1, 1), Error);
  EXPECT_THROW(Framebuffer(1, kMaxFramebufferSide + 1), Error);
  try {
    Framebuffer image(1, 100000);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("100000"), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(Framebuffer(kMaxFramebufferSide, 1));
}

TEST(Framebuffer, EqualityComparesSizeAndPixels) {
  Framebuffer a(2, 2, vec3(0.5f));
  Framebuffer b(2, 2, vec3(0.5f));
  EXPECT_EQ(a, b);
  b.at(1, 1).g = 0.5000001f;
  EXPECT_NE(a, b);
  EXPECT_NE(Framebuffer(2, 1), Framebuffer(1, 2));
}

// The transfer functions the PNG code and the metrics rely on.
TEST(Srgb, TransferFunctionsInvertEachOtherAndClamp) {
  for (int i = 0; i <= 1000; ++i) {
    const float v = static_cast<float>(i) / 1000.0f;
    EXPECT_NEAR(srgb_to_linear(linear_to_srgb(v)), v, 2e-6f);
    if (i > 0) {
      const float prev = static_cast<float>(i - 1) / 1000.0f;
      EXPECT_GT(linear_to_srgb(v), linear_to_srgb(prev)); // strictly increasing
    }
  }
  // The two pieces meet at the breakpoint (continuity of the exact piecewise OETF).
  const float knee = 0.0031308f;
  EXPECT_NEAR(12.92f * knee, 1.055f * std::pow(knee, 1.0f / 2.4f) - 0.055f, 1e-6f);
  EXPECT_EQ(linear_to_srgb(-1.0f), 0.0f);
  EXPECT_NEAR(linear_to_srgb(7.0f), 1.0f, 1e-6f);
  EXPECT_EQ(linear_to_srgb(std::numeric_limits<float>::quiet_NaN()), 0.0f);
  EXPECT_NEAR(linear_to_srgb(std::numeric_limits<float>::infinity()), 1.0f, 1e-6f);
}

// The table encoder gives the reference's byte for every float of [0, 1]: all 1,065,353,217 of
// them (about 4 s in the ci build), every 61st under AddressSanitizer, with the first and last
// float of every 16-bit run (where a wrong run code would show first) always included.
TEST(Srgb, TableEncodingEqualsTheReferenceOnEveryFloatOfTheUnitInterval) {
  const Srgb8Encoder& encode = Srgb8Encoder::get();
#if defined(SPECULA_TEST_ASAN)
  constexpr std::uint32_t stride = 61;
#else
  constexpr std::uint32_t stride = 1;
#endif
  constexpr std::uint32_t one = 0x3f800000u;
  std::uint64_t checked = 0, wrong = 0;
  std::uint32_t first_wrong = 0;
  const auto check = [&](std::uint32_t bits) {
    const float v = std::bit_cast<float>(bits);
    ++checked;
    if (encode(v) != encode_srgb8_reference(v) && wrong++ == 0) first_wrong = bits;
  };
  for (std::uint32_t bits = 0; bits <= one; bits += stride) check(bits);
  for (std::uint32_t run = 0; run < Srgb8Encoder::kRuns; ++run) {
    check(run << Srgb8Encoder::kRunShift);
    check(std::min(one, (run << Srgb8Encoder::kRunShift) | 0xFFFFu));
  }
  EXPECT_EQ(wrong, 0u) << "first at " << std::bit_cast<float>(first_wrong) << " of " << checked;
  EXPECT_GT(checked, std::uint64_t(one / stride));
}

// Each step starts where the reference's does: threshold k encodes to k, the float below it to
// k - 1; the steps rise one code at a time (none skipped), so every code 0…255 is reachable.
TEST(Srgb, TableThresholdsAreWhereTheReferenceStepsUp) {
  const Srgb8Encoder& encode = Srgb8Encoder::get();
  for (std::uint32_t k = 1; k < 256; ++k) {
    const float t = encode.threshold(k);
    const float below = std::nextafter(t, 0.0f);
    EXPECT_EQ(encode_srgb8_reference(t), k) << k;
    EXPECT_EQ(encode_srgb8_reference(below), k - 1) << k;
    EXPECT_EQ(encode(t), k) << k;
    EXPECT_EQ(encode(below), k - 1) << k;
    if (k > 1) {
      EXPECT_GT(t, encode.threshold(k - 1)) << k;
    }
  }
}

// Outside [0, 1] the clamp decides, as in the reference: negatives, -0, NaN and -inf give 0;
// above 1 and +inf give 255; seeded random floats of any magnitude agree with the reference.
TEST(Srgb, TableEncodingClampsAsTheReferenceDoes) {
  const Srgb8Encoder& encode = Srgb8Encoder::get();
  constexpr float inf = std::numeric_limits<float>::infinity();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (const float v : {-1.0f, -0.0f, -inf, nan, -std::numeric_limits<float>::denorm_min()})
    EXPECT_EQ(encode(v), 0) << v;
  for (const float v : {1.0f, 1.0000001f, 7.0f, 3e38f, inf}) EXPECT_EQ(encode(v), 255) << v;
  EXPECT_EQ(encode(std::numeric_limits<float>::denorm_min()),
            encode_srgb8_reference(std::numeric_limits<float>::denorm_min()));
  std::mt19937 rng(20261128);
  std::uniform_int_distribution<std::uint32_t> bits;
  for (int i = 0; i < 100000; ++i) {
    const float v = std::bit_cast<float>(bits(rng));
    ASSERT_EQ(encode(v), encode_srgb8_reference(v)) << v;
    ASSERT_EQ(encode_srgb8(v), encode_srgb8_reference(v)) << v;
  }
}

/// 3 × 2 pixels holding (x, y, 1): a ramp on each axis and a constant channel.
Framebuffer ramp_image() {
  Framebuffer img(3, 2);
  for (std::uint32_t y = 0; y < 2; ++y)
    for (std::uint32_t x = 0; x < 3; ++x) img.at(x, y) = vec3(float(x), float(y), 1.0f);
  return img;
}

TEST(ResampleNearest, SameSizeIsTheImageDoublingMakesBlocksHalvingTakesCentres) {
  const Framebuffer img = ramp_image();
  EXPECT_TRUE(resample_nearest(img, 3, 2) == img);
  const Framebuffer big = resample_nearest(img, 6, 4);
  for (std::uint32_t y = 0; y < 4; ++y)
    for (std::uint32_t x = 0; x < 6; ++x) EXPECT_EQ(big.at(x, y), img.at(x / 2, y / 2)) << x << "," << y;
  EXPECT_TRUE(resample_nearest(big, 3, 2) == img) << "halving undoes doubling";
  // Never out of range, at any ratio.
  const Framebuffer odd = resample_nearest(img, 7, 5);
  EXPECT_EQ(odd.at(6, 4), img.at(2, 1));
  EXPECT_EQ(odd.at(0, 0), img.at(0, 0));
  EXPECT_EQ(nearest_source(0, 1, 5), 2u) << "one sample takes the centre";
}

TEST(ResampleBilinear, SameSizeIsTheImageAndARampStaysARamp) {
  const Framebuffer img = ramp_image();
  EXPECT_TRUE(resample_bilinear(img, 3, 2) == img);
  // Doubling: destination centres at source x = (i + ½)/2 − ½, clamped to [0, 2]; the values of
  // a linear ramp are those positions themselves.
  const Framebuffer big = resample_bilinear(img, 6, 4);
  const float want_x[6] = {0.0f, 0.25f, 0.75f, 1.25f, 1.75f, 2.0f};
  const float want_y[4] = {0.0f, 0.25f, 0.75f, 1.0f};
  for (std::uint32_t y = 0; y < 4; ++y)
    for (std::uint32_t x = 0; x < 6; ++x) {
      EXPECT_FLOAT_EQ(big.at(x, y).x, want_x[x]) << x << "," << y;
      EXPECT_FLOAT_EQ(big.at(x, y).y, want_y[y]) << x << "," << y;
      EXPECT_EQ(big.at(x, y).z, 1.0f) << "a constant channel stays constant";
    }
  // A weight of 0 takes its sample alone, even beside an infinite one.
  Framebuffer spike(2, 1);
  spike.at(1, 0) = vec3(std::numeric_limits<float>::infinity());
  EXPECT_EQ(resample_bilinear(spike, 2, 1).at(0, 0), vec3(0.0f));
  const LinearTaps t = linear_source(0, 1, 5);
  EXPECT_EQ(t.lo, 2u);
  EXPECT_EQ(t.weight, 0.0f) << "one sample takes the centre";
}

} // namespace
} // namespace specula
