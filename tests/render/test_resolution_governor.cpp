// Dynamic resolution (specula/render/resolution_governor.h) against a synthetic frame-cost model:
// a fixed part plus a part proportional to the pixels, with seeded noise. The governor reaches
// the target from above and below, holds it without flicker, never leaves [min_scale, 1], and
// ignores measurements that are not times.

#include "specula/render/resolution_governor.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

namespace specula {
namespace {

/// ms of a frame at `scale`: fixed + per_full_frame · scale², times (1 ± noise).
struct CostModel {
  double fixed = 5.0, per_full_frame = 60.0, noise = 0.03;
  std::mt19937 rng{20261124};
  double operator()(float scale) {
    std::uniform_real_distribution<double> u(-noise, noise);
    return (fixed + per_full_frame * double(scale) * double(scale)) * (1.0 + u(rng));
  }
};

/// Runs `frames` frames; returns the scales used.
std::vector<float> run(ResolutionGovernor& g, CostModel& cost, int frames) {
  std::vector<float> scales;
  for (int i = 0; i < frames; ++i) {
    scales.push_back(g.scale());
    g.next(cost(g.scale()));
  }
  return scales;
}

TEST(ResolutionGovernor, ReachesTheTargetFromAboveAndHoldsItWithoutFlicker) {
  ResolutionGovernor g(33.3);
  CostModel cost; // 65 ms at full scale: about 0.7 holds 33 ms
  const std::vector<float> scales = run(g, cost, 120);
  // Within 10 frames the frame time is within 10% of the target.
  const double t10 = 5.0 + 60.0 * double(scales[10]) * double(scales[10]);
  EXPECT_NEAR(t10, 33.3, 3.4) << "scale " << scales[10];
  // After settling, few size changes (noise of ±3% sits inside the ±5% dead band).
  int changes = 0;
  for (std::size_t i = 61; i < scales.size(); ++i) changes += scales[i] != scales[i - 1];
  EXPECT_LE(changes, 2);
  // And the settled frames are within 10% of the target.
  for (std::size_t i = 60; i < scales.size(); ++i) {
    const double t = 5.0 + 60.0 * double(scales[i]) * double(scales[i]);
    EXPECT_NEAR(t, 33.3, 3.4) << "frame " << i;
  }
}

TEST(ResolutionGovernor, GoesBackUpWhenTheSceneGetsCheaperButNeverAboveOne) {
  ResolutionGovernor g(33.3);
  CostModel cost;
  cost.per_full_frame = 1000.0; // 67 ms even at the floor
  run(g, cost, 60);
  EXPECT_FLOAT_EQ(g.scale(), 0.25f) << "an expensive scene hits the floor, not below";
  cost.per_full_frame = 10.0; // cheap: back to full resolution
  const std::vector<float> scales = run(g, cost, 60);
  EXPECT_FLOAT_EQ(g.scale(), 1.0f);
  for (const float s : scales) {
    EXPECT_GE(s, 0.25f);
    EXPECT_LE(s, 1.0f);
  }
  // At most 25% per frame.
  for (std::size_t i = 1; i < scales.size(); ++i)
    EXPECT_LE(scales[i] / scales[i - 1], 1.25f + 1e-6f);
}

TEST(ResolutionGovernor, AFrameTimeThatIsNotATimeChangesNothingAndOffStaysAtOne) {
  ResolutionGovernor g(16.0, 0.5f);
  EXPECT_FLOAT_EQ(g.next(100.0), 51.0f / 64.0f) << "down by the most a frame allows, in 64ths";
  const float s = g.scale();
  for (const double bad : {std::numeric_limits<double>::quiet_NaN(),
                           std::numeric_limits<double>::infinity(), 0.0, -5.0})
    EXPECT_FLOAT_EQ(g.next(bad), s) << bad;
  for (int i = 0; i < 20; ++i) g.next(1000.0);
  EXPECT_FLOAT_EQ(g.scale(), 0.5f) << "min_scale";

  ResolutionGovernor off(0.0);
  EXPECT_FALSE(off.enabled());
  EXPECT_FLOAT_EQ(off.next(1000.0), 1.0f);
  ResolutionGovernor nan_target(std::numeric_limits<double>::quiet_NaN());
  EXPECT_FALSE(nan_target.enabled());
}

TEST(ResolutionGovernor, ScaledSizesStayWithinOnePixelAndTheFullSize) {
  EXPECT_EQ(ResolutionGovernor::scaled(960, 540, 0.5f), (std::pair<std::uint32_t, std::uint32_t>{480, 270}));
  EXPECT_EQ(ResolutionGovernor::scaled(960, 540, 1.0f), (std::pair<std::uint32_t, std::uint32_t>{960, 540}));
  EXPECT_EQ(ResolutionGovernor::scaled(3, 1, 0.01f), (std::pair<std::uint32_t, std::uint32_t>{1, 1}));
  EXPECT_EQ(ResolutionGovernor::scaled(960, 540, std::numeric_limits<float>::quiet_NaN()),
            (std::pair<std::uint32_t, std::uint32_t>{960, 540}));
  EXPECT_EQ(ResolutionGovernor::scaled(960, 540, 7.0f), (std::pair<std::uint32_t, std::uint32_t>{960, 540}));
}

} // namespace
} // namespace specula
