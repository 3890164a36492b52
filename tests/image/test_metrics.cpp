// RMSE and PSNR: properties that follow from their definitions, on seeded random images.

#include "specula/core/error.h"
#include "specula/image/metrics.h"
#include "specula/image/srgb.h"
#include "test_support.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace specula {
namespace {

TEST(Metrics, IdenticalImagesHaveZeroErrorAndInfinitePsnr) {
  const Framebuffer a = test::random_image(31, 17, 5);
  EXPECT_EQ(rmse(a, a), 0.0);
  EXPECT_EQ(rmse_srgb(a, a), 0.0);
  EXPECT_EQ(psnr(a, a), std::numeric_limits<double>::infinity());
}

TEST(Metrics, ConstantOffsetGivesRmseEqualToTheOffset) {
  const Framebuffer a = test::random_image(40, 30, 6);
  for (float d : {0.001f, 0.05f, 0.5f}) {
    Framebuffer b = a;
    for (vec3& p : b.pixels()) p += vec3(d);
    // a + d is rounded to float, so allow float precision of values up to 1.5.
    EXPECT_NEAR(rmse(a, b), d, 1e-6) << d;
    EXPECT_NEAR(rmse(b, a), d, 1e-6) << d;
  }
}

TEST(Metrics, RmseIsSymmetricAndGrowsWithNoiseAmplitude) {
  const Framebuffer a = test::random_image(32, 32, 8, 0.2f, 0.8f);
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> noise(-1.0f, 1.0f);
  Framebuffer pattern(32, 32);
  for (vec3& p : pattern.pixels()) p = vec3(noise(rng), noise(rng), noise(rng));
  double previous = 0.0;
  for (float amplitude : {0.01f, 0.05f, 0.2f}) {
    Framebuffer b = a;
    for (std::size_t i = 0; i < b.pixel_count(); ++i)
      b.pixels()[i] += amplitude * pattern.pixels()[i];
    EXPECT_EQ(rmse(a, b), rmse(b, a));
    EXPECT_GT(rmse(a, b), previous);
    previous = rmse(a, b);
  }
}

TEST(Metrics, PsnrIsTwentyLog10OfInverseRmse) {
  const Framebuffer a = test::random_image(20, 20, 10);
  for (std::uint32_t seed : {11u, 12u, 13u}) {
    const Framebuffer b = test::random_image(20, 20, seed);
    const double e = rmse(a, b);
    EXPECT_DOUBLE_EQ(psnr(a, b), 20.0 * std::log10(1.0 / e));
    EXPECT_DOUBLE_EQ(psnr_from_rmse(e), psnr(a, b));
  }
  // An RMSE of 0.1 is 20 dB, 0.01 is 40 dB: 20 dB per decade.
  EXPECT_NEAR(psnr_from_rmse(0.1), 20.0, 1e-12);
  EXPECT_NEAR(psnr_from_rmse(0.01), 40.0, 1e-12);
}

TEST(Metrics, SrgbRmseIgnoresDifferencesTheDisplayClamps) {
  // Both images are brighter than the display's white everywhere: encoded, they are identical.
  const Framebuffer a = test::random_image(8, 8, 14, 1.0f, 3.0f);
  const Framebuffer b = test::random_image(8, 8, 15, 1.0f, 3.0f);
  EXPECT_GT(rmse(a, b), 0.1);
  EXPECT_EQ(rmse_srgb(a, b), 0.0);
  // In the shadows the sRGB curve is steep, so a small linear difference weighs more there.
  const Framebuffer dark(8, 8, vec3(0.01f));
  const Framebuffer darker(8, 8, vec3(0.005f));
  EXPECT_GT(rmse_srgb(dark, darker), 5.0 * rmse(dark, darker));
}

TEST(Metrics, SizeMismatchThrows) {
  const Framebuffer a(4, 4);
  const Framebuffer b(4, 5);
  EXPECT_THROW((void)rmse(a, b), Error);
  EXPECT_THROW((void)rmse_srgb(a, b), Error);
  EXPECT_THROW((void)psnr(a, b), Error);
}

} // namespace
} // namespace specula
