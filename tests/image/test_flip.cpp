// LDR-FLIP: properties the paper's construction implies, on seeded images. No pasted reference
// numbers: identical images give 0, black vs white is near the top of the scale, the map stays in
// [0, 1], noise of larger amplitude scores higher, a one-pixel change stays local, and a farther
// viewer (more pixels per degree) sees fine noise less.

#include "specula/core/error.h"
#include "specula/image/flip.h"
#include "specula/image/image_io.h"
#include "specula/image/srgb.h"
#include "test_support.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace specula {
namespace {

/// A smooth seeded image in [0.2, 0.8]: a few random colour gradients, like a rendering.
Framebuffer smooth_image(std::uint32_t size, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.2f, 0.8f);
  const vec3 c00(u(rng), u(rng), u(rng));
  const vec3 c10(u(rng), u(rng), u(rng));
  const vec3 c01(u(rng), u(rng), u(rng));
  const vec3 c11(u(rng), u(rng), u(rng));
  Framebuffer image(size, size);
  for (std::uint32_t y = 0; y < size; ++y) {
    for (std::uint32_t x = 0; x < size; ++x) {
      const float s = static_cast<float>(x) / static_cast<float>(size - 1);
      const float t = static_cast<float>(y) / static_cast<float>(size - 1);
      image.at(x, y) = glm::mix(glm::mix(c00, c10, s), glm::mix(c01, c11, s), t);
    }
  }
  return image;
}

/// base + amplitude · (seeded uniform noise in [−1, 1]); the same pattern for every amplitude.
Framebuffer add_noise(const Framebuffer& base, float amplitude, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> noise(-1.0f, 1.0f);
  Framebuffer out = base;
  for (vec3& p : out.pixels()) p += amplitude * vec3(noise(rng), noise(rng), noise(rng));
  return out;
}

void expect_in_unit_range(const FlipResult& r) {
  for (float e : r.error_map) {
    ASSERT_TRUE(e >= 0.0f && e <= 1.0f) << e;
  }
  EXPECT_GE(r.mean, 0.0);
  EXPECT_LE(r.mean, 1.0);
}

TEST(Flip, IdenticalImagesGiveZeroEverywhere) {
  const Framebuffer a = test::random_image(48, 40, 21);
  const FlipResult r = flip(a, a);
  EXPECT_EQ(r.width, 48u);
  EXPECT_EQ(r.height, 40u);
  ASSERT_EQ(r.error_map.size(), a.pixel_count());
  EXPECT_EQ(*std::max_element(r.error_map.begin(), r.error_map.end()), 0.0f);
  EXPECT_EQ(r.mean, 0.0);
}

TEST(Flip, BlackAgainstWhiteIsNearTheMaximum) {
  // Uniform images: no features, so FLIP is the redistributed colour error of HyAB(black, white)
  // = 100 (lightness only), which lies above p_c·cmax and so maps into (p_t, 1] = (0.95, 1].
  const Framebuffer black(32, 32, vec3(0.0f));
  const Framebuffer white(32, 32, vec3(1.0f));
  const FlipResult r = flip(black, white);
  expect_in_unit_range(r);
  EXPECT_GT(r.mean, 0.95);
  const auto [lo, hi] = std::minmax_element(r.error_map.begin(), r.error_map.end());
  EXPECT_NEAR(*lo, *hi, 1e-5f); // uniform: the border replication adds nothing
  // Nothing scores higher than green against blue, the pair that defines cmax.
  const FlipResult gb =
      flip(Framebuffer(16, 16, vec3(0, 1, 0)), Framebuffer(16, 16, vec3(0, 0, 1)));
  EXPECT_NEAR(gb.mean, 1.0, 1e-4);
  EXPECT_LT(r.mean, gb.mean);
}

TEST(Flip, MapStaysInUnitRangeForWildInputs) {
  // HDR values, negatives and random colours: the LDR display model clamps them.
  for (std::uint32_t seed : {31u, 32u, 33u}) {
    const Framebuffer a = test::random_image(40, 36, seed, -0.5f, 2.0f);
    const Framebuffer b = test::random_image(40, 36, seed + 100, -0.5f, 2.0f);
    expect_in_unit_range(flip(a, b));
    expect_in_unit_range(flip(b, a));
  }
  // Hard black/white checkerboards against their inverse: maximal feature differences.
  Framebuffer checker(32, 32);
  Framebuffer inverse(32, 32);
  for (std::uint32_t y = 0; y < 32; ++y) {
    for (std::uint32_t x = 0; x < 32; ++x) {
      checker.at(x, y) = vec3(static_cast<float>((x + y) % 2));
      inverse.at(x, y) = vec3(1.0f) - checker.at(x, y);
    }
  }
  expect_in_unit_range(flip(checker, inverse));
  expect_in_unit_range(flip(checker, Framebuffer(32, 32, vec3(0.5f))));
}

TEST(Flip, GrowsWithNoiseAmplitude) {
  for (std::uint32_t seed : {41u, 42u}) {
    const Framebuffer base = smooth_image(64, seed);
    double previous = 0.0;
    for (float amplitude : {0.02f, 0.06f, 0.18f}) { // stays inside [0, 1]: no clamping
      const double mean = flip(base, add_noise(base, amplitude, seed + 7)).mean;
      EXPECT_GT(mean, previous) << "seed " << seed << " amplitude " << amplitude;
      previous = mean;
    }
  }
}

TEST(Flip, OnePixelChangeIsLocal) {
  const Framebuffer base = smooth_image(64, 51);
  Framebuffer changed = base;
  const std::uint32_t px = 30;
  const std::uint32_t py = 25;
  changed.at(px, py) = vec3(1.0f, 1.0f, 1.0f) - base.at(px, py);
  const FlipResult r = flip(base, changed);
  expect_in_unit_range(r);
  EXPECT_GT(r.mean, 0.0);
  EXPECT_LT(r.mean, 0.02);

  // The largest error is at (or right beside) the changed pixel.
  const auto worst = std::max_element(r.error_map.begin(), r.error_map.end());
  const auto worst_index = static_cast<std::uint32_t>(worst - r.error_map.begin());
  EXPECT_LE(std::abs(static_cast<int>(worst_index % 64) - static_cast<int>(px)), 1);
  EXPECT_LE(std::abs(static_cast<int>(worst_index / 64) - static_cast<int>(py)), 1);

  // Outside the support of the widest filter (the CSF radius, ceil(3·sqrt(0.04 / 2π²)·ppd) = 10
  // pixels at 67 ppd) the two images are filtered identically: exactly zero error there. And
  // most of the error sits close to the pixel.
  double near_sum = 0.0;
  for (std::uint32_t y = 0; y < 64; ++y) {
    for (std::uint32_t x = 0; x < 64; ++x) {
      const int distance = std::max(std::abs(static_cast<int>(x) - static_cast<int>(px)),
                                    std::abs(static_cast<int>(y) - static_cast<int>(py)));
      if (distance > 10) {
        EXPECT_EQ(r.at(x, y), 0.0f) << x << ", " << y;
      }
      if (distance <= 4) near_sum += r.at(x, y);
    }
  }
  EXPECT_GT(near_sum, 0.5 * r.mean * 64 * 64);
}

TEST(Flip, FartherViewersSeeFineNoiseLess) {
  // More pixels per degree = pixels subtend a smaller angle; the CSFs blur pixel noise more.
  const Framebuffer base = smooth_image(64, 61);
  const Framebuffer noisy = add_noise(base, 0.1f, 62);
  double previous = 1.0;
  for (double ppd : {20.0, kFlipDefaultPixelsPerDegree, 150.0}) {
    const double mean = flip(base, noisy, FlipOptions{ppd}).mean;
    EXPECT_LT(mean, previous) << ppd;
    previous = mean;
  }
}

TEST(Flip, DefaultViewingConditionIsThePapers) {
  // 0.7 m from a 0.7 m wide 3840-pixel monitor.
  EXPECT_NEAR(flip_pixels_per_degree(0.7, 0.7, 3840.0), kFlipDefaultPixelsPerDegree, 0.05);
}

TEST(Flip, RejectsMismatchedSizesAndBadViewingConditions) {
  EXPECT_THROW((void)flip(Framebuffer(8, 8), Framebuffer(8, 9)), Error);
  EXPECT_THROW((void)flip(Framebuffer(8, 8), Framebuffer(8, 8), FlipOptions{0.0}), Error);
  EXPECT_THROW((void)flip(Framebuffer(8, 8), Framebuffer(8, 8), FlipOptions{-3.0}), Error);
  EXPECT_THROW((void)flip(Framebuffer(8, 8), Framebuffer(8, 8), FlipOptions{std::nan("")}), Error);
}

TEST(Flip, TheMapIsTheSameWhateverTheBandHeight) {
  // Bands of rows keep the working memory to a few rows; every band height, including one row
  // (most halo) and bands that do not divide the height, must give the whole image's map bit
  // for bit: the filters reach across band edges, and the mean sums in the same order.
  const Framebuffer base = test::random_image(37, 53, 71);
  const Framebuffer other = add_noise(base, 0.2f, 72);
  const FlipResult whole = flip(base, other, FlipOptions{kFlipDefaultPixelsPerDegree, 0});
  for (const std::uint32_t band : {1u, 5u, 10u, 11u, 21u, 52u, 53u, 128u}) {
    const FlipResult banded = flip(base, other, FlipOptions{kFlipDefaultPixelsPerDegree, band});
    ASSERT_EQ(banded.error_map.size(), whole.error_map.size());
    EXPECT_TRUE(banded.error_map == whole.error_map) << "band of " << band << " rows";
    EXPECT_EQ(banded.mean, whole.mean) << "band of " << band << " rows";
  }
}

TEST(Flip, WorkingMemoryIsTheMapAndOneBand) {
  // 4 bytes per pixel for the map; the band buffers do not grow with the height.
  const std::uint64_t tall = flip_working_bytes(1000, 16000);
  const std::uint64_t short_one = flip_working_bytes(1000, 1000);
  EXPECT_EQ(tall - short_one, std::uint64_t{4} * 1000 * 15000);
  EXPECT_LT(flip_working_bytes(16384, 16384), std::uint64_t{5} * 16384 * 16384);
}

TEST(Flip, WorksOnImagesSmallerThanTheFilters) {
  const FlipResult r = flip(Framebuffer(1, 1, vec3(0.2f)), Framebuffer(1, 1, vec3(0.3f)));
  ASSERT_EQ(r.error_map.size(), 1u);
  EXPECT_GT(r.mean, 0.0);
  expect_in_unit_range(r);
}

TEST(Magma, RunsFromDarkPurpleToPaleYellowWithRisingLuminance) {
  const vec3 lo = magma(0.0f);
  const vec3 hi = magma(1.0f);
  EXPECT_LT(lo.r + lo.g + lo.b, 0.05f);
  EXPECT_GT(hi.r, 0.95f);
  EXPECT_GT(hi.g, 0.95f);
  EXPECT_GT(hi.r, hi.b); // yellowish
  EXPECT_EQ(magma(-1.0f), lo);
  EXPECT_EQ(magma(2.0f), hi);
  // Perceptually ordered: relative luminance of the decoded colour never decreases.
  float previous = -1.0f;
  for (int i = 0; i <= 512; ++i) {
    const vec3 c = magma(static_cast<float>(i) / 512.0f);
    const float y = 0.2126f * srgb_to_linear(c.r) + 0.7152f * srgb_to_linear(c.g) +
                    0.0722f * srgb_to_linear(c.b);
    EXPECT_GE(y, previous) << i;
    previous = y;
  }
}

TEST(Magma, HeatmapPngHasTheMapsSizeAndColours) {
  test::TempDir dir;
  const Framebuffer base = smooth_image(24, 71);
  Framebuffer changed = base;
  changed.at(12, 12) = vec3(1.0f);
  const FlipResult r = flip(base, changed);
  write_flip_heatmap(r, dir.file("heat.png"));
  const Framebuffer heat = read_png(dir.file("heat.png"));
  ASSERT_EQ(heat.width(), 24u);
  ASSERT_EQ(heat.height(), 24u);
  // A zero-error corner shows magma(0); the changed pixel is brighter.
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(linear_to_srgb(heat.at(0, 0)[c]), magma(0.0f)[c], 0.5f / 255.0f + 1e-5f);
  }
  EXPECT_GT(heat.at(12, 12).g + heat.at(12, 12).r, heat.at(0, 0).g + heat.at(0, 0).r);
}

} // namespace
} // namespace specula
