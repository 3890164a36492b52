// Progressive accumulation of the stochastic modes (render/accumulation.h, render_job_frame):
// the running mean, its sample offsets and when it starts again — first on synthetic frames,
// then through the schedule on the Cornell box in path and shadow modes.

#include "scene_builder.h"

#include "specula/core/error.h"
#include "specula/render/accumulation.h"
#include "specula/render/render_job.h"
#include "specula/scene/components.h"
#include "specula/scene/scene.h"
#include "specula/systems/schedule.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace specula {
namespace {

TraceSettings path_settings(std::uint32_t spp) {
  TraceSettings s;
  s.mode = TraceMode::Path;
  s.spp = spp;
  return s;
}

/// A frame whose every pixel holds `value` + its index (so pixels differ).
Framebuffer synthetic(std::uint32_t w, std::uint32_t h, float value) {
  Framebuffer f(w, h);
  for (std::size_t i = 0; i < f.pixel_count(); ++i)
    f.pixels()[i] = vec3(value + float(i), 2.0f * value, -value);
  return f;
}

TEST(Accumulation, TheMeanIsTheAverageOfTheFramesAndTheOffsetAdvancesBySamplesPerFrame) {
  Accumulation acc;
  const TraceSettings settings = path_settings(4);
  const Camera camera;
  Framebuffer mean(1, 1);
  const std::vector<float> values = {1.0f, 0.25f, 3.0f, 0.5f, 7.0f};
  for (std::size_t k = 0; k < values.size(); ++k) {
    const Accumulation::Frame frame = acc.begin(settings, camera, 3, 2, false, true);
    EXPECT_EQ(frame.sample_offset, 4u * k) << "frame " << k << " continues the sequences";
    EXPECT_EQ(frame.restarted, k == 0);
    const Framebuffer f = synthetic(3, 2, values[k]);
    acc.add(f, mean);
    if (k == 0) {
      EXPECT_EQ(mean, f) << "one frame's mean is the frame, bit for bit";
    }
    EXPECT_EQ(acc.samples(), 4u * (k + 1));
    EXPECT_EQ(acc.frames(), k + 1);
  }
  double sum = 0.0;
  for (const float v : values) sum += v;
  const float expected = float(sum / double(values.size()));
  for (std::size_t i = 0; i < mean.pixel_count(); ++i) {
    EXPECT_NEAR(mean.pixels()[i].x, expected + float(i), 1e-6f);
    EXPECT_NEAR(mean.pixels()[i].y, 2.0f * expected, 1e-6f);
    EXPECT_NEAR(mean.pixels()[i].z, -expected, 1e-6f);
  }
  EXPECT_EQ(acc.restarts(), 1u);
}

TEST(Accumulation, RestartsWhenTheSceneCameraSettingsOrSizeChangeAndOnlyThen) {
  Accumulation acc;
  TraceSettings settings = path_settings(2);
  settings.sample_offset = 10; // a restart returns here
  Camera camera;
  Framebuffer mean(1, 1);
  const auto frame = [&](bool scene_changed, std::uint32_t w = 4) {
    const Accumulation::Frame f = acc.begin(settings, camera, w, 4, scene_changed, true);
    acc.add(synthetic(w, 4, 1.0f), mean);
    return f;
  };
  EXPECT_TRUE(frame(false).restarted);
  EXPECT_FALSE(frame(false).restarted);
  EXPECT_EQ(frame(false).sample_offset, 14u);

  // What never changes the image does not restart.
  settings.threads = 1;
  settings.tile_size = 7;
  EXPECT_FALSE(frame(false).restarted);

  const auto restarted = [&](const char* what, bool scene_changed = false, std::uint32_t w = 4) {
    const Accumulation::Frame f = frame(scene_changed, w);
    EXPECT_TRUE(f.restarted) << what;
    EXPECT_EQ(f.sample_offset, 10u) << what;
    EXPECT_EQ(acc.samples(), settings.spp) << what;
    EXPECT_FALSE(frame(false, w).restarted) << what << ": then accumulates again";
  };
  restarted("the scene layer's delta", true);
  camera.position.x += 1e-3;
  restarted("the camera moved");
  camera.vertical_fov *= 0.5f;
  restarted("the camera zoomed");
  settings.seed = 3;
  restarted("the seed");
  settings.sampling = LightSampling::Light;
  restarted("the sampling");
  settings.max_depth = 2;
  restarted("the depth");
  settings.spp = 3;
  settings.sample_offset = 10;
  restarted("spp"); // (its offset then advances by 3: checked above for 2)
  restarted("the image size", false, 5);
}

TEST(Accumulation, OffShowsEachFrameAloneWhileTheOffsetStillAdvances) {
  Accumulation acc;
  const TraceSettings settings = path_settings(3);
  const Camera camera;
  Framebuffer mean(1, 1);
  for (std::uint32_t k = 0; k < 4; ++k) {
    const Accumulation::Frame frame = acc.begin(settings, camera, 2, 2, false, false);
    EXPECT_EQ(frame.sample_offset, 3u * k);
    EXPECT_EQ(frame.restarted, k == 0);
    const Framebuffer f = synthetic(2, 2, float(k));
    acc.add(f, mean);
    EXPECT_EQ(mean, f) << "frame " << k << " is shown as it is, not averaged";
    EXPECT_EQ(acc.samples(), 3u);
  }
  // Turning it on restarts: nothing of the frames before is in the mean.
  EXPECT_TRUE(acc.begin(settings, camera, 2, 2, false, true).restarted);
}

TEST(Accumulation, RestartsBeforeTheSequencesRunPastTheirLastSample) {
  Accumulation acc;
  TraceSettings settings = path_settings(2);
  settings.sample_offset = 0xFFFFFFFBu; // room for two frames of 2: ...FB, ...FD (ends at 2^32-1)
  const Camera camera;
  Framebuffer mean(1, 1);
  const std::vector<std::uint32_t> offsets = {0xFFFFFFFBu, 0xFFFFFFFDu, 0xFFFFFFFBu};
  for (std::size_t k = 0; k < offsets.size(); ++k) {
    const Accumulation::Frame f = acc.begin(settings, camera, 1, 1, false, true);
    EXPECT_EQ(f.sample_offset, offsets[k]) << k;
    EXPECT_EQ(f.restarted, k != 1) << k;
    acc.add(synthetic(1, 1, 1.0f), mean);
  }
}

TEST(Accumulation, AFrameOfAnotherSizeIsAnError) {
  Accumulation acc;
  Framebuffer mean(1, 1);
  EXPECT_THROW(acc.add(synthetic(2, 2, 0.0f), mean), Error) << "add without begin";
  (void)acc.begin(path_settings(1), Camera{}, 2, 2, false, true);
  EXPECT_THROW(acc.add(synthetic(3, 2, 0.0f), mean), Error);
}

// Through the schedule, with the real integrators (skipped while a mode is not available yet).

constexpr std::uint32_t kSize = 24;

Scene cornell() {
  return load_scene(std::filesystem::path(SPECULA_SOURCE_DIR) / "samples/scenes/cornell_box.json");
}

std::string backend() { return resolve_backend("auto"); }

/// Prepares a job in `mode` with `per_frame` samples per frame (spp or shadow samples).
void prepare(Scene& scene, TraceMode mode, std::uint32_t per_frame, std::uint32_t threads = 2,
             bool accumulate = true, std::uint32_t offset = 0) {
  RenderJob job;
  job.backend = backend();
  job.settings.mode = mode;
  job.settings.max_depth = scene.settings.max_depth;
  job.settings.background = scene.settings.background;
  job.settings.threads = threads;
  job.settings.spp = per_frame;
  job.settings.shadow_samples = per_frame;
  job.settings.seed = 7;
  job.settings.sample_offset = offset;
  job.accumulate = accumulate;
  job.image = Framebuffer(kSize, kSize);
  prepare_rendering(scene.registry, std::move(job));
}

/// One tick; false (and the test skipped) when the mode is not available in this build yet.
bool tick(Scene& scene, Schedule& schedule) {
  try {
    schedule.tick(scene.registry, 0.0);
  } catch (const UnavailableError&) {
    return false;
  }
  return true;
}

#define TICK_OR_SKIP(scene, schedule)                                                              \
  if (!tick(scene, schedule)) GTEST_SKIP() << "the mode is not available in this build yet"

const RenderJob& job_of(Scene& scene) { return scene.registry.resource<RenderJob>(); }

/// Relative closeness of two images that hold the same samples summed in another order.
void expect_same_samples(const Framebuffer& a, const Framebuffer& b, const std::string& what) {
  ASSERT_EQ(a.pixel_count(), b.pixel_count());
  std::size_t bad = 0;
  for (std::size_t i = 0; i < a.pixel_count(); ++i)
    for (int c = 0; c < 3; ++c) {
      const float x = a.pixels()[i][c], y = b.pixels()[i][c];
      if (!(std::abs(x - y) <= 1e-5f * std::max({1.0f, std::abs(x), std::abs(y)}))) ++bad;
    }
  EXPECT_EQ(bad, 0u) << what << ": channels that differ beyond float rounding";
}

class AccumulationRender : public ::testing::TestWithParam<TraceMode> {};

TEST_P(AccumulationRender, TheMeanOfNOneSampleFramesIsOneFrameOfNSamples) {
  constexpr std::uint32_t kFrames = 8;
  Scene progressive = cornell();
  prepare(progressive, GetParam(), 1);
  Schedule schedule;
  for (std::uint32_t k = 0; k < kFrames; ++k) {
    TICK_OR_SKIP(progressive, schedule);
    EXPECT_EQ(job_of(progressive).last.accumulated_samples, k + 1);
    EXPECT_EQ(job_of(progressive).last.accumulation_restarted, k == 0);
  }
  Scene whole = cornell();
  prepare(whole, GetParam(), kFrames);
  Schedule once;
  TICK_OR_SKIP(whole, once);
  EXPECT_EQ(job_of(whole).last.accumulated_samples, kFrames);
  expect_same_samples(job_of(progressive).image, job_of(whole).image,
                      "8 frames of 1 sample against 1 frame of 8");
  EXPECT_EQ(&job_of(progressive).noisy_image(), &job_of(progressive).image) << "no denoiser";
}

TEST_P(AccumulationRender, RestartsWhenAnEntityMovesOrTheCameraTurnsAndNotOtherwise) {
  Scene scene = cornell();
  ecs::Entity block = ecs::null_entity;
  scene.registry.view<Name>().each([&](ecs::Entity e, const Name& n) {
    if (n.value == "short block") block = e;
  });
  ASSERT_NE(block, ecs::null_entity);
  scene.registry.emplace_or_replace<Kinematics>(block, Kinematics{Kinematics::Type::Free});
  prepare(scene, GetParam(), 2);
  Schedule schedule;
  const auto frame = [&] {
    if (!tick(scene, schedule)) return false;
    return job_of(scene).last.accumulation_restarted;
  };
  TICK_OR_SKIP(scene, schedule);
  EXPECT_TRUE(job_of(scene).last.accumulation_restarted);
  for (int k = 0; k < 3; ++k) EXPECT_FALSE(frame()) << "nothing moved: frame " << k + 2;
  EXPECT_EQ(job_of(scene).last.accumulated_samples, 8u);
  const Framebuffer still = job_of(scene).image;

  scene.registry.get<Transform>(block).translation.y += 0.05f;
  EXPECT_TRUE(frame()) << "the block moved";
  EXPECT_EQ(job_of(scene).last.accumulated_samples, 2u);
  EXPECT_FALSE(frame());
  EXPECT_EQ(job_of(scene).last.accumulated_samples, 4u);

  scene.registry.view<Camera>().each([](Camera& c) { c.look_at.x += 0.01; });
  EXPECT_TRUE(frame()) << "the camera turned";
  EXPECT_FALSE(frame());
  EXPECT_NE(job_of(scene).image, still);
}

TEST_P(AccumulationRender, WithAccumulationOffEachFrameIsItsOwnSamples) {
  Scene off = cornell();
  prepare(off, GetParam(), 2, 2, false);
  Schedule schedule;
  for (int k = 0; k < 3; ++k) TICK_OR_SKIP(off, schedule);
  EXPECT_EQ(job_of(off).last.accumulated_samples, 2u);
  // The third frame alone: samples [4, 6) of every pixel, not the mean of [0, 6).
  Scene third = cornell();
  prepare(third, GetParam(), 2, 2, true, 4);
  Schedule once;
  TICK_OR_SKIP(third, once);
  EXPECT_EQ(job_of(off).image, job_of(third).image);
}

TEST_P(AccumulationRender, TheAccumulatedImageIsTheSameOnOneAndTwoThreads) {
  Framebuffer images[2] = {Framebuffer(1, 1), Framebuffer(1, 1)};
  for (std::uint32_t threads : {1u, 2u}) {
    Scene scene = cornell();
    prepare(scene, GetParam(), 1, threads);
    Schedule schedule;
    for (int k = 0; k < 3; ++k) TICK_OR_SKIP(scene, schedule);
    images[threads - 1] = job_of(scene).image;
  }
  EXPECT_EQ(images[0], images[1]);
}

TEST_P(AccumulationRender, DenoisingKeepsTheNoisyMeanBesideTheImage) {
  Scene plain = cornell();
  prepare(plain, GetParam(), 1);
  Schedule schedule;
  for (int k = 0; k < 2; ++k) TICK_OR_SKIP(plain, schedule);

  Scene denoised = cornell();
  prepare(denoised, GetParam(), 1);
  denoised.registry.resource<RenderJob>().denoise = DenoiseSettings{};
  Schedule again;
  for (int k = 0; k < 2; ++k) TICK_OR_SKIP(denoised, again);
  const RenderJob& job = job_of(denoised);
  EXPECT_EQ(job.noisy_image(), job_of(plain).image) << "the same samples, not filtered";
  EXPECT_EQ(&job.noisy_image(), &job.noisy);
  EXPECT_EQ(job.image.width(), kSize);
  EXPECT_EQ(job.last.accumulated_samples, 2u * samples_per_frame(job.settings));
  EXPECT_GT(job.last.denoise_ms, 0.0);
  EXPECT_EQ(job.guides.size(), std::size_t{kSize} * kSize);
}

INSTANTIATE_TEST_SUITE_P(Modes, AccumulationRender,
                         ::testing::Values(TraceMode::Path, TraceMode::Shadow),
                         [](const auto& param) {
                           return std::string(trace_mode_name(param.param));
                         });

TEST(RenderJob, RefusesSampleCountsOrOffsetsOutOfRangeAndADenoiserWithoutNoise) {
  const auto refused = [](auto edit) {
    Scene scene = cornell();
    RenderJob job;
    job.backend = backend();
    job.settings.mode = TraceMode::Path;
    job.image = Framebuffer(4, 4);
    edit(job);
    EXPECT_THROW(prepare_rendering(scene.registry, std::move(job)), Error);
  };
  refused([](RenderJob& j) { j.settings.spp = 0; });
  refused([](RenderJob& j) { j.settings.spp = kMaxSpp + 1; });
  refused([](RenderJob& j) { j.settings.shadow_samples = 0; });
  refused([](RenderJob& j) { j.settings.shadow_samples = kMaxShadowSamples + 1; });
  refused([](RenderJob& j) {
    j.settings.spp = 4;
    j.settings.sample_offset = 0xFFFFFFFDu; // 3 samples left
  });
  refused([](RenderJob& j) {
    j.settings.mode = TraceMode::Whitted;
    j.denoise = DenoiseSettings{};
  });
}

} // namespace
} // namespace specula
