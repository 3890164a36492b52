// Golden images: the sample scenes at 128×128 in cast and Whitted mode against committed
// references (linear EXR), within a stated tolerance: PSNR ≥ 40 dB and mean FLIP ≤ 0.01. Embree
// picks its ISA at run time, so hits at triangle edges may differ in the last bits across CPUs;
// a real regression (a wrong normal, a missing bounce, a shadow leak) costs far more than that.
//
// SPECULA_UPDATE_GOLDEN=1 rewrites the references (review the PNGs written beside them first).

#include "specula/image/flip.h"
#include "specula/image/image_io.h"
#include "specula/image/metrics.h"
#include "specula/render/render_job.h"
#include "specula/scene/scene.h"
#include "specula/systems/schedule.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>

namespace specula {
namespace {

namespace fs = std::filesystem;

constexpr double kMinPsnr = 40.0;
constexpr double kMaxFlip = 0.01;

Framebuffer render_sample(const std::string& scene_name, TraceMode mode) {
  Scene scene =
      load_scene(fs::path(SPECULA_SOURCE_DIR) / "samples/scenes" / (scene_name + ".json"));
  RenderJob job;
  job.settings.mode = mode;
  job.settings.max_depth = scene.settings.max_depth;
  job.settings.background = scene.settings.background;
  job.settings.threads = 2;
  job.image = Framebuffer(128, 128);
  prepare_rendering(scene.registry, std::move(job));
  Schedule schedule;
  schedule.tick(scene.registry, 0.0);
  return scene.registry.resource<RenderJob>().image;
}

struct Case {
  std::string scene;
  TraceMode mode;
};

class Golden : public ::testing::TestWithParam<Case> {};

TEST_P(Golden, MatchesTheReference) {
  const Case& c = GetParam();
  const std::string name = c.scene + "_" + trace_mode_name(c.mode);
  const fs::path reference = fs::path(SPECULA_TEST_DATA_DIR) / "golden" / (name + ".exr");
  const Framebuffer image = render_sample(c.scene, c.mode);
  if (std::getenv("SPECULA_UPDATE_GOLDEN") != nullptr) {
    fs::create_directories(reference.parent_path());
    write_exr(image, reference);
    write_png(image, fs::path(reference).replace_extension(".png"));
    GTEST_SKIP() << "rewrote " << reference;
  }
  ASSERT_TRUE(fs::exists(reference))
      << reference << " is missing (SPECULA_UPDATE_GOLDEN=1 writes it)";
  const Framebuffer golden = read_exr(reference);
  const double p = psnr(golden, image);
  const double f = flip(golden, image).mean;
  if (p < kMinPsnr || f > kMaxFlip) {
    const fs::path out = fs::temp_directory_path() / ("specula_golden_" + name);
    write_png(image, out.string() + "_actual.png");
    write_flip_heatmap(flip(golden, image), out.string() + "_flip.png");
    ADD_FAILURE() << name << ": PSNR " << p << " dB, FLIP " << f << "; wrote " << out << "_*.png";
  }
  // The image is not trivially dark or blown out: the scene was actually lit and traced.
  double mean = 0.0;
  for (const vec3& px : image.pixels()) mean += (px.x + px.y + px.z) / 3.0;
  mean /= double(image.pixel_count());
  EXPECT_GT(mean, 0.01) << name;
  EXPECT_LT(mean, 5.0) << name;
}

std::string case_name(const ::testing::TestParamInfo<Case>& info) {
  return info.param.scene + "_" + trace_mode_name(info.param.mode);
}

INSTANTIATE_TEST_SUITE_P(Samples, Golden,
                         ::testing::Values(Case{"cornell_box", TraceMode::Cast},
                                           Case{"cornell_box", TraceMode::Whitted},
                                           Case{"mirror_spheres_0", TraceMode::Cast},
                                           Case{"mirror_spheres_0", TraceMode::Whitted},
                                           Case{"mirror_spheres_8", TraceMode::Cast},
                                           Case{"mirror_spheres_8", TraceMode::Whitted},
                                           Case{"mirror_spheres_32", TraceMode::Whitted}),
                         case_name);

} // namespace
} // namespace specula
