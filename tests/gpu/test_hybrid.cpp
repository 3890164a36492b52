// Hybrid mode (engine/gpu/raster_primary.h): primary visibility rasterised into a visibility
// buffer, the rest of the frame traced in compute, against the fully traced device frame of the
// same settings: the same instance and triangle at ≥ 99.9% of pixels (edges may differ by
// coverage rules), bit-identical hits and pixels wherever they agree, PSNR ≥ 45 dB, at most a
// quarter of the primary rays traced after all (instance boundaries), for cast and
// Whitted, on the Cornell box, on a mesh scene with a rotated, non-uniformly scaled dynamic
// instance (hits in object space), and far from the world origin; the single kernel's hybrid
// image equal to the wavefront's; no ray cut by the driver.
#include "device_scenes.h"
#include "specula/core/error.h"
#include "specula/gpu/device_renderer.h"
#include "specula/gpu/gpu_scene.h"
#include "specula/gpu/vulkan_tracer.h"
#include "specula/image/metrics.h"
#include "specula/trace/render_frame.h"

#include <gtest/gtest.h>

#include <cstring>
#include <iostream>
#include <string>

namespace specula {
namespace {

constexpr std::uint32_t kWidth = 96, kHeight = 72;

#define SPECULA_NEED_DRAWING_DEVICE()                                                              \
  if (!test::have_device(true)) GTEST_SKIP() << "no Vulkan device that draws on this machine"

/// A finely tessellated static sphere on a floor, a mirror, and a dynamic sphere rotated and
/// scaled unevenly (its hits are found in object space), under one point light.
void mesh_scene(ecs::Registry& reg) {
  using test::add_mesh;
  using test::at;
  using test::primitive;
  Material grey, mirror, blue;
  grey.base_color = vec3(0.7f);
  mirror.base_color = vec3(0.9f);
  mirror.reflectivity = 0.8f;
  blue.base_color = vec3(0.2f, 0.3f, 0.8f);
  add_mesh(reg, primitive("plane", 1, vec3(6.0f)), at(vec3(0)), grey);
  add_mesh(reg, primitive("sphere", 0.8f, vec3(1), 96, 48), at(vec3(-0.6f, 0.8f, 0.0f)), mirror);
  add_mesh(reg, primitive("sphere", 0.5f, vec3(1), 64, 32),
           at(vec3(0.9f, 0.6f, 0.4f), vec3(1.4f, 0.8f, 1.0f),
              glm::normalize(quat(0.9f, 0.2f, 0.3f, 0.1f))),
           blue, Kinematics::Type::Free);
  test::add_point_light(reg, vec3(1.0f, 3.0f, 2.0f), 6.0f);
}

Camera mesh_camera() {
  Camera c;
  c.position = dvec3(0.3, 1.6, 3.6);
  c.look_at = dvec3(0.0, 0.6, 0.0);
  c.vertical_fov = glm::radians(45.0f);
  return c;
}

TraceSettings settings_for(TraceMode mode) {
  TraceSettings s;
  s.mode = mode;
  s.max_depth = 5;
  s.threads = 2;
  return s;
}

/// One device frame with traced or rasterised primary visibility.
struct Frame {
  Framebuffer image{kWidth, kHeight};
  std::vector<gpu::GpuHit> hits; ///< wavefront only
  gpu::GpuTraceCounters counters;
};

/// `chunk`: wavefront frames in chunks of at most this many pixels (0: in one piece; no hits).
Frame render(const SceneLayer& layer, const Camera& camera, const TraceSettings& s,
             gpu::PrimaryVisibility primary, gpu::Execution execution = gpu::Execution::wavefront,
             std::uint32_t chunk = 0) {
  auto context = gpu::Context::create();
  gpu::GpuScene scene(*context, gpu::GpuStructure::bvh);
  scene.update(layer);
  gpu::DeviceRenderer renderer(*context, scene, execution, primary);
  renderer.set_chunk_limit(chunk);
  Frame f;
  FrameStats stats;
  renderer.render(layer, camera, s, f.image, stats, f.counters);
  if (execution == gpu::Execution::wavefront && chunk == 0) f.hits = renderer.primary_hits();
  return f;
}

/// Compares a hybrid frame with the traced one: agreement on the primary triangle, and wherever
/// they agree, the same hit bits and the same pixel.
void expect_hybrid_matches(const SceneLayer& layer, const Camera& camera, TraceMode mode,
                           const char* scene) {
  const TraceSettings s = settings_for(mode);
  const Frame traced = render(layer, camera, s, gpu::PrimaryVisibility::trace);
  const Frame hybrid = render(layer, camera, s, gpu::PrimaryVisibility::raster);
  ASSERT_EQ(traced.hits.size(), hybrid.hits.size());
  std::uint32_t same = 0, hit_bits_differ = 0, pixels_differ = 0, covered = 0;
  for (std::size_t i = 0; i < traced.hits.size(); ++i) {
    const gpu::GpuHit& a = traced.hits[i];
    const gpu::GpuHit& b = hybrid.hits[i];
    covered += a.instance != gpu::kNoIndex ? 1u : 0u;
    if (a.instance != b.instance || (a.instance != gpu::kNoIndex && a.primitive != b.primitive))
      continue;
    ++same;
    hit_bits_differ += std::memcmp(&a, &b, sizeof a) != 0 ? 1u : 0u;
    pixels_differ += traced.image.pixels()[i] != hybrid.image.pixels()[i] ? 1u : 0u;
  }
  const double agree = double(same) / double(traced.hits.size());
  const double p = psnr(traced.image, hybrid.image);
  std::cout << scene << " " << trace_mode_name(mode) << ": primary agreement " << 100.0 * agree
            << "% of " << traced.hits.size() << " pixels (" << covered << " covered), PSNR " << p
            << " dB, retraced " << hybrid.counters.retraced << ", rays " << hybrid.counters.rays
            << " (traced " << traced.counters.rays << ")\n";
  EXPECT_GT(covered, traced.hits.size() / 2) << "the camera must see the scene";
  // Instance boundaries are traced after all (frame_visibility.comp); the rest must come from
  // the raster pass, or the comparison would be of two traced frames.
  EXPECT_LT(hybrid.counters.retraced, traced.hits.size() / 4);
  EXPECT_GE(agree, 0.999);
  EXPECT_EQ(hit_bits_differ, 0u) << "pixels on the same triangle with different t, u, v or normal";
  EXPECT_EQ(pixels_differ, 0u) << "pixels on the same triangle with different radiance";
  EXPECT_GE(p, 45.0);
  EXPECT_EQ(traced.counters.cut, 0u);
  EXPECT_EQ(hybrid.counters.cut, 0u);

  // The single kernel settles the same primary hits at the root of its walks.
  const Frame single =
      render(layer, camera, s, gpu::PrimaryVisibility::raster, gpu::Execution::single_kernel);
  EXPECT_EQ(test::differing_pixels(single.image, hybrid.image), 0u)
      << "pixels where the single kernel's hybrid frame differs";
  EXPECT_EQ(single.counters.rays, hybrid.counters.rays);
  EXPECT_EQ(single.counters.retraced, hybrid.counters.retraced);
  EXPECT_EQ(single.counters.cut, 0u);

  // A wavefront frame in chunks (one raster pass, each chunk's primaries settled from it) is the
  // frame in one piece.
  const Frame chunked =
      render(layer, camera, s, gpu::PrimaryVisibility::raster, gpu::Execution::wavefront, 1000);
  EXPECT_EQ(test::differing_pixels(chunked.image, hybrid.image), 0u)
      << "pixels where the hybrid frame in chunks differs";
  EXPECT_EQ(chunked.counters.rays, hybrid.counters.rays);
  EXPECT_EQ(chunked.counters.retraced, hybrid.counters.retraced);
}

class Hybrid : public ::testing::TestWithParam<TraceMode> {};

TEST_P(Hybrid, CornellBoxMatchesTheTracedFrame) {
  SPECULA_NEED_DRAWING_DEVICE();
  ecs::Registry reg;
  test::cornell(reg);
  test::TracedWorld world(reg, "native-bvh", test::device_mirror_options());
  expect_hybrid_matches(world.layer, test::cornell_camera(), GetParam(), "cornell");
}

TEST_P(Hybrid, MeshSceneWithADynamicInstanceMatchesTheTracedFrame) {
  SPECULA_NEED_DRAWING_DEVICE();
  ecs::Registry reg;
  mesh_scene(reg);
  test::TracedWorld world(reg, "native-bvh", test::device_mirror_options());
  ASSERT_FALSE(world.tables().instances.empty());
  expect_hybrid_matches(world.layer, mesh_camera(), GetParam(), "mesh");
}

TEST_P(Hybrid, FarFromTheWorldOriginMatchesTheTracedFrame) {
  SPECULA_NEED_DRAWING_DEVICE();
  ecs::Registry reg;
  mesh_scene(reg);
  // Everything, the camera included, a long way from the world origin: the layer's render
  // origin follows the camera, and both passes work relative to it.
  const dvec3 offset(-3.0e7, 1.0e6, 2.0e7);
  reg.view<Transform>().each([&](Transform& t) { t.translation += offset; });
  Camera camera = mesh_camera();
  camera.position += offset;
  camera.look_at += offset;
  reg.emplace<Camera>(reg.create(), camera);
  test::TracedWorld world(reg, "native-bvh", test::device_mirror_options());
  ASSERT_GT(glm::length(world.layer.render_origin()), 1e6) << "the render origin must move";
  expect_hybrid_matches(world.layer, camera, GetParam(), "far");
}

INSTANTIATE_TEST_SUITE_P(Modes, Hybrid, ::testing::Values(TraceMode::Cast, TraceMode::Whitted),
                         [](const auto& param_info) {
                           return std::string(trace_mode_name(param_info.param));
                         });

} // namespace
} // namespace specula
