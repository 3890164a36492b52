// The edge-avoiding à-trous denoiser: what it must keep (constants, edges in the guides, albedo
// textures, misses), what it must remove (noise on a flat region), determinism across thread
// counts and clear errors. Synthetic images from seeded generators.

#include "specula/core/error.h"
#include "specula/image/denoise.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <tuple>
#include <vector>

namespace specula {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

/// Guides of a flat wall facing the camera at depth 5, albedo 1.
GuideBuffers flat_guides(std::uint32_t width, std::uint32_t height) {
  GuideBuffers guides;
  guides.resize(std::size_t(width) * height);
  for (std::size_t i = 0; i < guides.size(); ++i) {
    guides.albedo[i] = vec3(1.0f);
    guides.normal[i] = vec3(0.0f, 0.0f, 1.0f);
    guides.depth[i] = 5.0f;
  }
  return guides;
}

/// `mean` plus uniform noise in [−amplitude, amplitude) per channel.
Framebuffer noisy_image(std::uint32_t width, std::uint32_t height, float mean, float amplitude,
                        std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> noise(-amplitude, amplitude);
  Framebuffer image(width, height);
  for (vec3& p : image.pixels()) p = vec3(mean) + vec3(noise(rng), noise(rng), noise(rng));
  return image;
}

/// Mean and variance of the red channel over the columns [x0, x1) of every row.
struct Moments {
  double mean = 0.0;
  double variance = 0.0;
};
Moments red_moments(const Framebuffer& image, std::uint32_t x0, std::uint32_t x1) {
  double sum = 0.0;
  double sum2 = 0.0;
  std::size_t count = 0;
  for (std::uint32_t y = 0; y < image.height(); ++y)
    for (std::uint32_t x = x0; x < x1; ++x) {
      const double v = image.at(x, y).x;
      sum += v;
      sum2 += v * v;
      ++count;
    }
  const double mean = sum / double(count);
  return {mean, sum2 / double(count) - mean * mean};
}

TEST(Denoise, ConstantImageStaysConstant) {
  // Whatever the guides (here a wall with a step in depth and normal, and a varying albedo the
  // colour follows), a constant lighting comes back unchanged.
  const std::uint32_t w = 48, h = 40;
  GuideBuffers guides = flat_guides(w, h);
  Framebuffer image(w, h);
  for (std::uint32_t y = 0; y < h; ++y)
    for (std::uint32_t x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      guides.albedo[i] = vec3(0.2f + 0.6f * float((x / 4 + y / 4) % 2), 0.5f, 1.0f);
      if (x >= w / 2) {
        guides.normal[i] = vec3(1.0f, 0.0f, 0.0f);
        guides.depth[i] = 9.0f;
      }
      image.at(x, y) = vec3(0.7f) * guides.albedo[i];
    }
  Framebuffer out(1, 1);
  atrous_denoise(image, guides, DenoiseSettings{}, out);
  ASSERT_EQ(out.width(), w);
  ASSERT_EQ(out.height(), h);
  for (std::size_t i = 0; i < out.pixel_count(); ++i)
    for (int c = 0; c < 3; ++c)
      ASSERT_NEAR(out.pixels()[i][c], image.pixels()[i][c], 1e-6f) << i << " channel " << c;
}

TEST(Denoise, NoiseVarianceOnAFlatRegionDropsByALargeFactor) {
  const std::uint32_t w = 96, h = 96;
  const Framebuffer image = noisy_image(w, h, 0.5f, 0.25f, 1);
  Framebuffer out(1, 1);
  atrous_denoise(image, flat_guides(w, h), DenoiseSettings{}, out);
  // The centre region, away from the borders where fewer taps exist.
  const Moments before = red_moments(image, 16, 80);
  const Moments after = red_moments(out, 16, 80);
  EXPECT_GT(before.variance, 0.015); // uniform in ±0.25: 0.25²/3 ≈ 0.021
  EXPECT_LT(after.variance, before.variance / 50.0)
      << "before " << before.variance << ", after " << after.variance;
  EXPECT_NEAR(after.mean, 0.5, 0.01); // smoothing, not shifting
}

/// A 64 × 32 image: the left half noisy around 0.2, the right half around 0.8. Returns the
/// denoised means of the four columns on each side of the edge with the colour weight off, so
/// only the guides can keep the halves apart.
std::pair<double, double> means_beside_edge(const GuideBuffers& guides) {
  const std::uint32_t w = 64, h = 32;
  Framebuffer image = noisy_image(w, h, 0.0f, 0.1f, 2);
  for (std::uint32_t y = 0; y < h; ++y)
    for (std::uint32_t x = 0; x < w; ++x) image.at(x, y) += vec3(x < w / 2 ? 0.2f : 0.8f);
  DenoiseSettings settings;
  settings.sigma_color = kInf;
  Framebuffer out(1, 1);
  atrous_denoise(image, guides, settings, out);
  return {red_moments(out, w / 2 - 4, w / 2).mean, red_moments(out, w / 2, w / 2 + 4).mean};
}

TEST(Denoise, StepInTheNormalGuideIsNotBlurredAcross) {
  GuideBuffers guides = flat_guides(64, 32);
  // Without an edge in the guides the halves bleed into each other (the test has teeth)...
  const auto [left_blurred, right_blurred] = means_beside_edge(guides);
  EXPECT_GT(left_blurred, 0.3);
  EXPECT_LT(right_blurred, 0.7);
  // ...with a 90° crease (same depth) they keep their own means.
  for (std::size_t i = 0; i < guides.size(); ++i)
    if (i % 64 >= 32) guides.normal[i] = vec3(1.0f, 0.0f, 0.0f);
  const auto [left, right] = means_beside_edge(guides);
  EXPECT_NEAR(left, 0.2, 0.01);
  EXPECT_NEAR(right, 0.8, 0.01);
}

TEST(Denoise, StepInTheDepthGuideIsNotBlurredAcross) {
  // A wall in front of another (same normal), both slanted (depth growing along x): the slope is
  // smoothed over, the step is not.
  GuideBuffers guides = flat_guides(64, 32);
  for (std::size_t i = 0; i < guides.size(); ++i) {
    const float x = float(i % 64);
    guides.depth[i] = i % 64 < 32 ? 4.0f + 0.02f * x : 6.0f + 0.02f * x;
  }
  const auto [left, right] = means_beside_edge(guides);
  EXPECT_NEAR(left, 0.2, 0.01);
  EXPECT_NEAR(right, 0.8, 0.01);
}

TEST(Denoise, SlantedPlaneIsSmoothedLikeAFlatOne) {
  // Depth growing steeply across a plane (a floor seen at a grazing angle) is predicted from the
  // depth gradient, not mistaken for edges.
  const std::uint32_t w = 96, h = 96;
  GuideBuffers guides = flat_guides(w, h);
  for (std::size_t i = 0; i < guides.size(); ++i) guides.depth[i] = 2.0f + 0.1f * float(i / w);
  const Framebuffer image = noisy_image(w, h, 0.5f, 0.25f, 3);
  Framebuffer out(1, 1);
  atrous_denoise(image, guides, DenoiseSettings{}, out);
  EXPECT_LT(red_moments(out, 16, 80).variance, red_moments(image, 16, 80).variance / 50.0);
}

TEST(Denoise, AlbedoTextureStaysSharp) {
  // A checkerboard albedo (0.35 / 0.65 in 4-pixel cells) under noisy uniform light 1, the noise
  // about as strong as the texture's contrast: divided by the albedo the lighting is smoothed and
  // the texture multiplied back crisp.
  const std::uint32_t w = 64, h = 64;
  GuideBuffers guides = flat_guides(w, h);
  Framebuffer image = noisy_image(w, h, 1.0f, 0.3f, 4);
  for (std::uint32_t y = 0; y < h; ++y)
    for (std::uint32_t x = 0; x < w; ++x) {
      const std::size_t i = std::size_t(y) * w + x;
      guides.albedo[i] = vec3((x / 4 + y / 4) % 2 == 0 ? 0.35f : 0.65f);
      image.at(x, y) *= guides.albedo[i];
    }
  const auto mean_error = [&](const Framebuffer& out) {
    double sum = 0.0;
    for (std::uint32_t y = 8; y < h - 8; ++y)
      for (std::uint32_t x = 8; x < w - 8; ++x)
        sum += std::abs(out.at(x, y).x - guides.albedo[std::size_t(y) * w + x].x);
    return sum / double((w - 16) * (h - 16));
  };
  Framebuffer out(1, 1);
  atrous_denoise(image, guides, DenoiseSettings{}, out);
  EXPECT_LT(mean_error(out), 0.02); // the cells keep their albedo (the noise was ±0.3·albedo)
  EXPECT_LT(mean_error(out), mean_error(image) / 5.0);
  // Without demodulation (albedo guide 1) the colour weight cannot tell texture from noise: the
  // cells blur into each other.
  GuideBuffers plain = guides;
  for (vec3& a : plain.albedo) a = vec3(1.0f);
  Framebuffer blurred(1, 1);
  atrous_denoise(image, plain, DenoiseSettings{}, blurred);
  EXPECT_GT(mean_error(blurred), 10.0 * mean_error(out));
}

TEST(Denoise, MissesAreCopiedThroughAndNeverTaps) {
  // A bright sky (misses) beside a noisy wall: the sky is untouched, and the wall's pixels next to
  // it take nothing from it.
  const std::uint32_t w = 64, h = 32;
  GuideBuffers guides = flat_guides(w, h);
  Framebuffer image = noisy_image(w, h, 0.3f, 0.1f, 5);
  for (std::uint32_t y = 0; y < h; ++y)
    for (std::uint32_t x = w / 2; x < w; ++x) {
      guides.depth[std::size_t(y) * w + x] = kInf;
      guides.normal[std::size_t(y) * w + x] = vec3(0.0f);
      image.at(x, y) = vec3(50.0f + float(x), 0.0f, float(y));
    }
  DenoiseSettings settings;
  settings.sigma_color = kInf;
  Framebuffer out(1, 1);
  atrous_denoise(image, guides, settings, out);
  for (std::uint32_t y = 0; y < h; ++y)
    for (std::uint32_t x = w / 2; x < w; ++x) ASSERT_EQ(out.at(x, y), image.at(x, y)) << x;
  EXPECT_NEAR(red_moments(out, w / 2 - 2, w / 2).mean, 0.3, 0.01);
}

/// The filter written the plain way, a pixel at a time with std::exp, as Dammertz et al. describe
/// it: what the vectorised implementation must match (up to its exponential's 2·10⁻⁴).
/// With `variance`, the variance-guided colour weight: the 3×3 binomial prefilter of the
/// variances, exp(−|Δc|²/(σ_v²·Var)) per tap, and each level's variance Σw²·Var / (Σw)².
Framebuffer plain_atrous(const Framebuffer& noisy, const GuideBuffers& g, const DenoiseSettings& s,
                         const std::vector<float>& variance = {}) {
  const int w = int(noisy.width()), h = int(noisy.height());
  const auto index = [&](int x, int y) { return std::size_t(y) * std::size_t(w) + std::size_t(x); };
  const auto usable = [&](int x, int y) {
    return x >= 0 && y >= 0 && x < w && y < h && std::isfinite(g.depth[index(x, y)]);
  };
  const auto demod = [](float a) { return a >= 1e-3f ? a : 1.0f; };
  std::vector<vec3> c(noisy.pixel_count());
  for (std::size_t i = 0; i < c.size(); ++i)
    c[i] =
        noisy.pixels()[i] / vec3(demod(g.albedo[i].x), demod(g.albedo[i].y), demod(g.albedo[i].z));
  const float b3[5] = {1.0f / 16, 1.0f / 4, 3.0f / 8, 1.0f / 4, 1.0f / 16};
  const auto slope = [&](int x, int y, int dx, int dy) {
    const float d = g.depth[index(x, y)];
    const bool before = usable(x - dx, y - dy), after = usable(x + dx, y + dy);
    const float b = before ? d - g.depth[index(x - dx, y - dy)] : 0.0f;
    const float a = after ? g.depth[index(x + dx, y + dy)] - d : 0.0f;
    if (before && after) return std::abs(b) <= std::abs(a) ? b : a;
    return before ? b : a;
  };
  std::vector<float> var(c.size(), 0.0f);
  if (!variance.empty())
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        if (!usable(x, y)) continue;
        double sum = 0.0, weights = 0.0;
        for (int j = -1; j <= 1; ++j)
          for (int i = -1; i <= 1; ++i) {
            if (!usable(x + i, y + j)) continue;
            const double k = double((2 - std::abs(i)) * (2 - std::abs(j)));
            sum += k * double(std::min(variance[index(x + i, y + j)], 1e30f));
            weights += k;
          }
        var[index(x, y)] = float(sum / weights);
      }
  for (std::uint32_t level = 0; level < s.iterations; ++level) {
    const int step = 1 << level;
    const float sc = s.sigma_color / float(1 << level);
    std::vector<vec3> next = c;
    std::vector<float> next_var = var;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        if (!usable(x, y)) continue;
        const std::size_t p = index(x, y);
        vec3 sum(0.0f);
        float weights = 0.0f, var_sum = 0.0f;
        for (int j = -2; j <= 2; ++j)
          for (int i = -2; i <= 2; ++i) {
            const int qx = x + i * step, qy = y + j * step;
            if (!usable(qx, qy)) continue;
            const std::size_t q = index(qx, qy);
            const vec3 dc = c[q] - c[p], dn = g.normal[q] - g.normal[p];
            const float predicted = g.depth[p] + slope(x, y, 1, 0) * float(i * step) +
                                    slope(x, y, 0, 1) * float(j * step);
            const float dd = (g.depth[q] - predicted) / (s.sigma_depth * g.depth[p]);
            const float colour_scale =
                variance.empty() ? sc * sc : s.sigma_variance * s.sigma_variance * var[p] + 1e-30f;
            const float e = glm::dot(dc, dc) / colour_scale +
                            glm::dot(dn, dn) / (s.sigma_normal * s.sigma_normal) + dd * dd;
            const float weight = e < 30.0f ? b3[i + 2] * b3[j + 2] * std::exp(-e) : 0.0f;
            sum += weight * c[q];
            weights += weight;
            var_sum += weight * weight * var[q];
          }
        next[p] = sum / weights;
        next_var[p] = var_sum / (weights * weights);
      }
    c = next;
    var = next_var;
  }
  Framebuffer out(noisy.width(), noisy.height());
  for (std::size_t i = 0; i < c.size(); ++i)
    out.pixels()[i] =
        std::isfinite(g.depth[i])
            ? c[i] * vec3(demod(g.albedo[i].x), demod(g.albedo[i].y), demod(g.albedo[i].z))
            : noisy.pixels()[i];
  return out;
}

/// Guides with every feature: a curved normal field, a depth step and a slope, misses, albedo
/// with a (nearly) black channel.
GuideBuffers varied_guides(std::uint32_t w, std::uint32_t h, std::uint32_t seed) {
  GuideBuffers guides = flat_guides(w, h);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  for (std::size_t i = 0; i < guides.size(); ++i) {
    const float x = float(i % w) / float(w) - 0.5f, y = float(i / w) / float(h) - 0.5f;
    guides.normal[i] = glm::normalize(vec3(x, y, 0.6f));
    guides.depth[i] = unit(rng) < 0.05f ? kInf : 3.0f + (x > 0.1f ? 1.0f : 0.0f) + 0.5f * y;
    guides.albedo[i] = vec3(0.2f + 0.8f * unit(rng), 0.5f, 0.0005f);
  }
  return guides;
}

TEST(Denoise, MatchesTheFilterWrittenPlainly) {
  // Widths that are not whole SIMD steps, and images narrower than the widest level's reach.
  for (const auto& [w, h, levels] : {std::tuple{37u, 23u, 5u}, std::tuple{13u, 9u, 5u},
                                     std::tuple{1u, 1u, 3u}, std::tuple{6u, 40u, 4u}}) {
    const GuideBuffers guides = varied_guides(w, h, w);
    const Framebuffer image = noisy_image(w, h, 0.6f, 0.5f, h);
    DenoiseSettings settings;
    settings.iterations = levels;
    Framebuffer out(1, 1);
    atrous_denoise(image, guides, settings, out);
    const Framebuffer expected = plain_atrous(image, guides, settings);
    for (std::size_t i = 0; i < out.pixel_count(); ++i)
      for (int c = 0; c < 3; ++c)
        ASSERT_NEAR(out.pixels()[i][c], expected.pixels()[i][c],
                    2e-3f * std::abs(expected.pixels()[i][c]) + 1e-6f)
            << w << "x" << h << " pixel " << i << " channel " << c;
  }
}

TEST(Denoise, VarianceGuidedMatchesTheFilterWrittenPlainly) {
  for (const auto& [w, h, levels] : {std::tuple{37u, 23u, 5u}, std::tuple{13u, 9u, 5u},
                                     std::tuple{1u, 1u, 3u}, std::tuple{6u, 40u, 4u}}) {
    const GuideBuffers guides = varied_guides(w, h, w + 1);
    const Framebuffer image = noisy_image(w, h, 0.6f, 0.5f, h + 1);
    // Variances over four decades, some pixels converged (0) and some unknown (+inf).
    std::mt19937 rng(w * h);
    std::uniform_real_distribution<float> decade(-4.0f, 0.0f);
    std::vector<float> variance(image.pixel_count());
    for (std::size_t i = 0; i < variance.size(); ++i)
      variance[i] = i % 11 == 3 ? 0.0f : i % 17 == 5 ? kInf : std::pow(10.0f, decade(rng));
    DenoiseSettings settings;
    settings.iterations = levels;
    Framebuffer out(1, 1);
    atrous_denoise(image, guides, settings, out, variance);
    const Framebuffer expected = plain_atrous(image, guides, settings, variance);
    for (std::size_t i = 0; i < out.pixel_count(); ++i)
      for (int c = 0; c < 3; ++c)
        ASSERT_NEAR(out.pixels()[i][c], expected.pixels()[i][c],
                    2e-3f * std::abs(expected.pixels()[i][c]) + 1e-6f)
            << w << "x" << h << " pixel " << i << " channel " << c;
  }
}

/// A flat wall lit 0.5 with noise ±0.05, one pixel (a firefly) at 40, with the variances a few
/// frames would show: the firefly's far above the rest. Returns the firefly's denoised value.
float denoised_firefly(bool variance_guided) {
  const std::uint32_t w = 32, h = 32, fx = 16, fy = 16;
  const GuideBuffers guides = flat_guides(w, h);
  Framebuffer image = noisy_image(w, h, 0.5f, 0.05f, 9);
  image.at(fx, fy) = vec3(40.0f);
  std::vector<float> variance(image.pixel_count(), 0.05f * 0.05f / 3.0f / 8.0f);
  variance[fy * w + fx] = 40.0f * 40.0f / 8.0f; // one sample of 8 was that bright
  Framebuffer out(1, 1);
  atrous_denoise(image, guides, DenoiseSettings{}, out,
                 variance_guided ? variance : std::vector<float>{});
  return out.at(fx, fy).x;
}

TEST(Denoise, VarianceGuidedWeightSpreadsAFireflyTheFixedOneKeeps) {
  // The fixed colour weight sees the firefly as an edge and keeps it (the test has teeth)...
  EXPECT_GT(denoised_firefly(false), 30.0f);
  // ...its variance lets the variance-guided weight average it with the wall.
  EXPECT_LT(denoised_firefly(true), 2.0f);
}

TEST(Denoise, VarianceGuidedWeightKeepsAConvergedStepAndSmoothsANoisyOne) {
  // A shadow's edge on one flat wall (the guides cannot see it): lighting 0.2 | 0.8 plus noise.
  const std::uint32_t w = 64, h = 32;
  const GuideBuffers guides = flat_guides(w, h);
  Framebuffer image = noisy_image(w, h, 0.0f, 0.01f, 10);
  for (std::uint32_t y = 0; y < h; ++y)
    for (std::uint32_t x = 0; x < w; ++x) image.at(x, y) += vec3(x < w / 2 ? 0.2f : 0.8f);
  const auto beside_edge = [&](float var) {
    Framebuffer out(1, 1);
    atrous_denoise(image, guides, DenoiseSettings{}, out,
                   std::vector<float>(image.pixel_count(), var));
    return std::pair{red_moments(out, w / 2 - 2, w / 2).mean,
                     red_moments(out, w / 2, w / 2 + 2).mean};
  };
  // Converged (the noise is within its small variance): the edge stays where it is.
  const auto [left, right] = beside_edge(0.01f * 0.01f / 3.0f);
  EXPECT_NEAR(left, 0.2, 0.01);
  EXPECT_NEAR(right, 0.8, 0.01);
  // Estimates that could be off by the step itself are averaged across it.
  const auto [left_noisy, right_noisy] = beside_edge(0.25f);
  EXPECT_GT(left_noisy, 0.3);
  EXPECT_LT(right_noisy, 0.7);
}

TEST(Denoise, LuminanceMomentsGiveTheVarianceOfTheMean) {
  // Two pixels: one seeing 1, 2, 3, 6 (under albedo 0.5: lighting twice that), one a constant 4
  // under albedo 1 with a NaN frame left out.
  GuideBuffers guides;
  guides.resize(2);
  guides.albedo = {vec3(0.5f), vec3(1.0f)};
  LuminanceMoments moments;
  moments.reset(2);
  const float values[] = {1.0f, 2.0f, 3.0f, 6.0f};
  for (int k = 0; k < 4; ++k) {
    Framebuffer frame(2, 1);
    frame.at(0, 0) = vec3(values[k]);
    frame.at(1, 0) = k == 2 ? vec3(std::numeric_limits<float>::quiet_NaN()) : vec3(4.0f);
    moments.add(frame, guides);
    if (k == 0) {
      EXPECT_TRUE(moments.variance_of_mean().empty()) << "one frame has no variance";
    }
  }
  EXPECT_EQ(moments.frames(), 4u);
  const std::vector<float> v = moments.variance_of_mean();
  ASSERT_EQ(v.size(), 2u);
  // Lighting 2, 4, 6, 12: mean 6, sample variance (16 + 4 + 0 + 36) / 3, of the mean / 4.
  EXPECT_NEAR(v[0], 56.0 / 3.0 / 4.0, 1e-4);
  EXPECT_EQ(v[1], 0.0f);
  // A pixel with one finite value has an unknown variance.
  moments.reset(2);
  for (int k = 0; k < 2; ++k) {
    Framebuffer frame(2, 1);
    frame.at(0, 0) = vec3(k == 0 ? 1.0f : kInf);
    moments.add(frame, guides);
  }
  EXPECT_EQ(moments.variance_of_mean()[0], kInf);
  // Sizes other than reset()'s are refused.
  EXPECT_THROW(moments.add(Framebuffer(3, 1), guides), Error);
}

TEST(Denoise, OutputMayBeTheInput) {
  const std::uint32_t w = 40, h = 24;
  const GuideBuffers guides = flat_guides(w, h);
  Framebuffer image = noisy_image(w, h, 0.5f, 0.2f, 6);
  Framebuffer separate(1, 1);
  atrous_denoise(image, guides, DenoiseSettings{}, separate);
  atrous_denoise(image, guides, DenoiseSettings{}, image);
  EXPECT_EQ(image, separate);
}

TEST(Denoise, IdenticalForOneAndTwoThreads) {
  const std::uint32_t w = 123, h = 77;
  const GuideBuffers guides = varied_guides(w, h, 7);
  const Framebuffer image = noisy_image(w, h, 1.0f, 0.9f, 8);
  DenoiseSettings settings;
  settings.threads = 1;
  Framebuffer one(1, 1);
  atrous_denoise(image, guides, settings, one);
  settings.threads = 2;
  Framebuffer two(1, 1);
  atrous_denoise(image, guides, settings, two);
  EXPECT_EQ(one, two);
  EXPECT_NE(one, image); // it did filter
  // The variance-guided weight too.
  std::vector<float> variance(image.pixel_count());
  for (std::size_t i = 0; i < variance.size(); ++i) variance[i] = 0.01f * float(1 + i % 7);
  atrous_denoise(image, guides, settings, two, variance);
  settings.threads = 1;
  atrous_denoise(image, guides, settings, one, variance);
  EXPECT_EQ(one, two);
  EXPECT_NE(one, image);
}

TEST(Denoise, EightLanesGiveTheBitsOfFour) {
  if (!__builtin_cpu_supports("avx2")) GTEST_SKIP() << "this CPU has no AVX2";
  // Widths that leave every remainder of a group of eight, both colour weights.
  for (const std::uint32_t w : {1u, 5u, 8u, 13u, 37u}) {
    const std::uint32_t h = 19;
    const GuideBuffers guides = varied_guides(w, h, w + 2);
    const Framebuffer image = noisy_image(w, h, 0.6f, 0.5f, w + 3);
    std::vector<float> variance(image.pixel_count());
    for (std::size_t i = 0; i < variance.size(); ++i) variance[i] = 0.003f * float(1 + i % 5);
    for (const bool guided : {false, true}) {
      DenoiseSettings settings;
      settings.lanes = 4;
      Framebuffer four(1, 1), eight(1, 1);
      atrous_denoise(image, guides, settings, four, guided ? variance : std::vector<float>{});
      settings.lanes = 8;
      atrous_denoise(image, guides, settings, eight, guided ? variance : std::vector<float>{});
      EXPECT_EQ(four, eight) << w << (guided ? " variance-guided" : " fixed");
      EXPECT_NE(four, image);
    }
  }
}

TEST(Denoise, MismatchedSizesAndBadSettingsThrow) {
  const Framebuffer image(16, 8);
  Framebuffer out(1, 1);
  for (int which = 0; which < 3; ++which) {
    GuideBuffers guides = flat_guides(16, 8);
    if (which == 0) guides.albedo.pop_back();
    if (which == 1) guides.normal.resize(16 * 9);
    if (which == 2) guides.depth.clear();
    EXPECT_THROW(atrous_denoise(image, guides, DenoiseSettings{}, out), Error) << which;
  }
  const GuideBuffers guides = flat_guides(16, 8);
  for (int which = 0; which < 4; ++which) {
    DenoiseSettings settings;
    if (which == 0) settings.iterations = 13;
    if (which == 1) settings.sigma_color = 0.0f;
    if (which == 2) settings.sigma_normal = -1.0f;
    if (which == 3) settings.sigma_depth = std::numeric_limits<float>::quiet_NaN();
    EXPECT_THROW(atrous_denoise(image, guides, settings, out), Error) << which;
  }
  for (const std::uint32_t lanes : {1u, 2u, 16u}) {
    DenoiseSettings settings;
    settings.lanes = lanes;
    EXPECT_THROW(atrous_denoise(image, guides, settings, out), Error) << lanes;
  }
  // A variance of the wrong size, or a σ_v that is not a positive finite number.
  EXPECT_THROW(atrous_denoise(image, guides, DenoiseSettings{}, out, std::vector<float>(127, 1.0f)),
               Error);
  for (const float sigma : {0.0f, -2.0f, kInf, std::numeric_limits<float>::quiet_NaN()}) {
    DenoiseSettings settings;
    settings.sigma_variance = sigma;
    EXPECT_THROW(atrous_denoise(image, guides, settings, out, std::vector<float>(128, 1.0f)), Error)
        << sigma;
  }
  // The message names the guide and both sizes.
  GuideBuffers short_depth = flat_guides(16, 8);
  short_depth.depth.resize(5);
  try {
    atrous_denoise(image, short_depth, DenoiseSettings{}, out);
    FAIL() << "no throw";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("depth"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("128"), std::string::npos) << e.what();
  }
}

} // namespace
} // namespace specula
