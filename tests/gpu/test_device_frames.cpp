// Whole frames on the device (engine/gpu/device_renderer.h) against the CPU integrators of the
// same settings on the reference backend: cast and Whitted images within PSNR 45 dB, primary
// visibility agreeing on 99.9% of pixels, the wavefront and the single kernel giving the same
// image, no ray cut by the driver, resumption after a small traversal budget, a frame in chunks
// equal to the frame in one piece, a moved object
// seen where it moved, a dynamic object seen while it exists (the top level's code compiled in
// and out), a morphing mesh shaded with its sampled normals, each wavefront stage's device time,
// and a lost device reported as such.
#include "device_scenes.h"
#include "specula/core/error.h"
#include "specula/gpu/device_renderer.h"
#include "specula/gpu/gpu_scene.h"
#include "specula/gpu/vulkan_tracer.h"
#include "specula/image/metrics.h"
#include "specula/trace/render_frame.h"

#include <gtest/gtest.h>

#include <iostream>
#include <string>
#include <vector>

namespace specula {
namespace {

using test::cornell;
using test::cornell_camera;

constexpr std::uint32_t kWidth = 64, kHeight = 48;

/// The CPU reference: the native backend over the same structure as the device (a BVH over the
/// static set), whose traversal trace.glsl mirrors step for step. Against Embree the images differ
/// at edges lying on pixel centres (this box's walls meet there): native-bvh itself agrees with
/// Embree on 99.6-99.8% of primary hits here, and the device on exactly as many.
std::string reference_backend() { return "native-bvh"; }

/// A device, its scene and a renderer of one execution style over a layer.
struct Device {
  std::unique_ptr<gpu::Context> context;
  std::unique_ptr<gpu::GpuScene> scene;
  std::unique_ptr<gpu::DeviceRenderer> renderer;
  gpu::GpuTraceCounters counters;
  FrameStats stats; ///< the last frame's

  Device(const SceneLayer& layer, gpu::Execution execution) {
    context = gpu::Context::create();
    scene = std::make_unique<gpu::GpuScene>(*context, gpu::GpuStructure::bvh);
    scene->update(layer);
    renderer = std::make_unique<gpu::DeviceRenderer>(*context, *scene, execution);
  }
  Framebuffer render(const SceneLayer& layer, const Camera& camera, const TraceSettings& s) {
    Framebuffer out(kWidth, kHeight);
    stats = FrameStats{};
    renderer->render(layer, camera, s, out, stats, counters);
    return out;
  }
};

TraceSettings settings_for(TraceMode mode) {
  TraceSettings s;
  s.mode = mode;
  s.max_depth = 5;
  s.threads = 2;
  return s;
}

/// The Cornell box traced on the reference backend, its camera, and the settings of a mode.
struct CornellBox {
  ecs::Registry reg;
  test::TracedWorld world;
  Camera camera = test::cornell_camera();
  TraceSettings settings;

  explicit CornellBox(TraceMode mode)
      : world(built(reg), reference_backend(), test::device_mirror_options()),
        settings(settings_for(mode)) {}
  static ecs::Registry& built(ecs::Registry& r) {
    test::cornell(r);
    return r;
  }
};

/// Fraction of pixels whose primary ray hit the same instance on the CPU backend.
double primary_agreement(const test::TracedWorld& world, const Camera& camera,
                         std::span<const std::uint32_t> device) {
  const CameraRays rays(camera, kWidth, kHeight, world.layer.render_origin());
  std::uint32_t same = 0;
  for (std::uint32_t y = 0; y < kHeight; ++y)
    for (std::uint32_t x = 0; x < kWidth; ++x)
      same += world.intersect(rays.ray(x, y)).instance == device[y * kWidth + x] ? 1u : 0u;
  return double(same) / double(kWidth * kHeight);
}

class DeviceFrames : public ::testing::TestWithParam<TraceMode> {};

TEST_P(DeviceFrames, MatchTheCpuImageAndPrimaryHits) {
  SPECULA_NEED_DEVICE();
  const CornellBox box(GetParam());
  const test::TracedWorld& world = box.world;
  const Camera& camera = box.camera;
  const TraceSettings& s = box.settings;
  Framebuffer cpu(kWidth, kHeight);
  const FrameStats cpu_stats = render_frame(*world.tracer, world.layer, camera, s, cpu);
  for (const gpu::Execution e : {gpu::Execution::wavefront, gpu::Execution::single_kernel}) {
    Device device(world.layer, e);
    const Framebuffer image = device.render(world.layer, camera, s);
    const double p = psnr(cpu, image);
    const double agree = primary_agreement(world, camera, device.renderer->primary_instances());
    std::cout << trace_mode_name(s.mode) << (e == gpu::Execution::wavefront ? " wavefront" : " single")
              << ": PSNR " << p << " dB, primary agreement " << 100.0 * agree << "%, rays "
              << device.counters.rays << " (CPU " << cpu_stats.rays.total() << ")\n";
    EXPECT_GE(p, 45.0);
    EXPECT_GE(agree, 0.999);
    EXPECT_EQ(device.counters.cut, 0u);
  }
}

TEST_P(DeviceFrames, WavefrontAndSingleKernelGiveTheSameImage) {
  SPECULA_NEED_DEVICE();
  const CornellBox box(GetParam());
  const test::TracedWorld& world = box.world;
  const Camera& camera = box.camera;
  const TraceSettings& s = box.settings;
  Device wavefront(world.layer, gpu::Execution::wavefront);
  Device single(world.layer, gpu::Execution::single_kernel);
  const Framebuffer a = wavefront.render(world.layer, camera, s);
  const Framebuffer b = single.render(world.layer, camera, s);
  EXPECT_EQ(test::differing_pixels(a, b), 0u) << "pixels that differ between the styles";
  EXPECT_EQ(wavefront.counters.rays, single.counters.rays);
  EXPECT_EQ(wavefront.counters.cut, 0u);
  EXPECT_EQ(single.counters.cut, 0u);
}

// A budget far below a ray's walk: traces stop mid-walk, save their traversal state and go on in
// a later wave (wavefront) or dispatch (single kernel), so the frame comes out as with the full
// budget (same pixels, same rays), none cut by the driver and none started over for want of a
// pool slot.
TEST_P(DeviceFrames, SmallBudgetResumesToTheSameImage) {
  SPECULA_NEED_DEVICE();
  const CornellBox box(GetParam());
  const test::TracedWorld& world = box.world;
  const Camera& camera = box.camera;
  const TraceSettings& s = box.settings;
  for (const gpu::Execution e : {gpu::Execution::wavefront, gpu::Execution::single_kernel}) {
    SCOPED_TRACE(e == gpu::Execution::wavefront ? "wavefront" : "single kernel");
    Device full(world.layer, e), small(world.layer, e);
    small.renderer->set_budget(16);
    const Framebuffer a = full.render(world.layer, camera, s);
    const Framebuffer b = small.render(world.layer, camera, s);
    EXPECT_EQ(full.counters.resumed, 0u);
    // Traces stopped mid-walk and the frame still finished: started over from the root, a
    // wavefront ray needing more than 16 steps never would (the frame used to end in an error).
    EXPECT_GT(small.counters.resumed, 0u);
    EXPECT_EQ(small.counters.restarted, 0u);
    EXPECT_EQ(small.counters.cut, 0u);
    EXPECT_EQ(full.counters.cut, 0u);
    EXPECT_EQ(full.counters.rays, small.counters.rays);
    EXPECT_EQ(test::differing_pixels(a, b), 0u);
  }
}

// A frame whose trees would outgrow one storage buffer of nodes (1024² Whitted frames on
// lavapipe's 128 MiB) is rendered in chunks of pixels, each with every node slot: the image, the
// primary hits and the ray counts are those of the frame in one piece, no ray dropped.
TEST_P(DeviceFrames, AFrameInChunksEqualsTheFrameInOnePiece) {
  SPECULA_NEED_DEVICE();
  const CornellBox box(GetParam());
  const test::TracedWorld& world = box.world;
  const Camera& camera = box.camera;
  const TraceSettings& s = box.settings;
  Device whole(world.layer, gpu::Execution::wavefront),
      chunked(world.layer, gpu::Execution::wavefront);
  chunked.renderer->set_chunk_limit(1000); // 3072 pixels: chunks of 1000, 1000, 1000 and 72
  const Framebuffer a = whole.render(world.layer, camera, s);
  const Framebuffer b = chunked.render(world.layer, camera, s);
  EXPECT_EQ(whole.renderer->wave_chunks(), 1u);
  EXPECT_EQ(chunked.renderer->wave_chunks(), 4u);
  EXPECT_EQ(test::differing_pixels(a, b), 0u) << "pixels that differ";
  EXPECT_EQ(whole.counters.rays, chunked.counters.rays);
  EXPECT_GE(chunked.counters.rays, std::uint64_t(kWidth) * kHeight);
  EXPECT_EQ(whole.stats.rays.dropped, 0u);
  EXPECT_EQ(chunked.stats.rays.dropped, 0u);
  EXPECT_EQ(chunked.counters.cut, 0u);
  const std::vector<std::uint32_t> pa(whole.renderer->primary_instances().begin(),
                                      whole.renderer->primary_instances().end());
  const std::vector<std::uint32_t> pb(chunked.renderer->primary_instances().begin(),
                                      chunked.renderer->primary_instances().end());
  EXPECT_EQ(pa, pb);
  EXPECT_THROW((void)chunked.renderer->primary_hits(), Error) << "hits of the last chunk only";
}

INSTANTIATE_TEST_SUITE_P(Modes, DeviceFrames,
                         ::testing::Values(TraceMode::Cast, TraceMode::Whitted),
                         [](const auto& param_info) { return std::string(trace_mode_name(param_info.param)); });

TEST(DeviceFramesScene, AMovedObjectRendersAtItsNewPosition) {
  SPECULA_NEED_DEVICE();
  ecs::Registry reg;
  test::cornell(reg);
  Material m;
  m.base_color = vec3(0.2f, 0.2f, 0.9f);
  const ecs::Entity ball = test::add_mesh(reg, test::primitive("sphere", 0.2f, vec3(1), 12, 6),
                                          test::at(vec3(0.0f, 1.0f, 0.5f)), m,
                                          Kinematics::Type::Free);
  test::TracedWorld world(reg, reference_backend(), test::device_mirror_options());
  const Camera camera = test::cornell_camera();
  const TraceSettings s = settings_for(TraceMode::Whitted);
  Device device(world.layer, gpu::Execution::wavefront);
  (void)device.render(world.layer, camera, s);
  reg.get<Transform>(ball).translation = vec3(0.0f, 1.5f, 0.5f);
  world.update(reg);
  device.scene->update(world.layer);
  const Framebuffer image = device.render(world.layer, camera, s);
  Framebuffer cpu(kWidth, kHeight);
  (void)render_frame(*world.tracer, world.layer, camera, s, cpu);
  EXPECT_GE(psnr(cpu, image), 45.0);
  EXPECT_GE(primary_agreement(world, camera, device.renderer->primary_instances()), 0.999);
}

// The frame kernels compile the top level's code out for a scene without dynamic instances
// (frame_common.glsl's kTopCode): a dynamic object that appears must be seen in the next frame,
// and once it is gone the frame must be the first one again, in both execution styles.
TEST(DeviceFramesScene, ATopLevelThatComesAndGoesRendersEveryFrameRight) {
  SPECULA_NEED_DEVICE();
  const Camera camera = test::cornell_camera();
  const TraceSettings s = settings_for(TraceMode::Whitted);
  for (const gpu::Execution e : {gpu::Execution::single_kernel, gpu::Execution::wavefront}) {
    SCOPED_TRACE(e == gpu::Execution::wavefront ? "wavefront" : "single kernel");
    ecs::Registry reg;
    test::cornell(reg);
    test::TracedWorld world(reg, reference_backend(), test::device_mirror_options());
    Device device(world.layer, e);
    const auto matches_cpu = [&](const char* frame, const Framebuffer& image) {
      SCOPED_TRACE(frame);
      Framebuffer cpu(kWidth, kHeight);
      (void)render_frame(*world.tracer, world.layer, camera, s, cpu);
      EXPECT_GE(psnr(cpu, image), 45.0);
      EXPECT_GE(primary_agreement(world, camera, device.renderer->primary_instances()), 0.999);
      EXPECT_EQ(device.counters.cut, 0u);
    };
    ASSERT_FALSE(device.scene->has_top_level());
    const Framebuffer before = device.render(world.layer, camera, s);
    matches_cpu("before the ball", before);
    const std::vector<std::uint32_t> primary_before(device.renderer->primary_instances().begin(),
                                                    device.renderer->primary_instances().end());

    Material m;
    m.base_color = vec3(0.2f, 0.2f, 0.9f);
    const ecs::Entity ball = test::add_mesh(reg, test::primitive("sphere", 0.2f, vec3(1), 12, 6),
                                            test::at(vec3(0.0f, 1.0f, 0.5f)), m,
                                            Kinematics::Type::Free);
    world.update(reg);
    device.scene->update(world.layer);
    ASSERT_TRUE(device.scene->has_top_level());
    matches_cpu("with the ball", device.render(world.layer, camera, s));
    std::uint32_t changed = 0;
    for (std::size_t i = 0; i < primary_before.size(); ++i)
      changed += device.renderer->primary_instances()[i] != primary_before[i] ? 1u : 0u;
    EXPECT_GT(changed, 20u) << "primary hits on the dynamic ball";

    reg.destroy(ball);
    world.update(reg);
    device.scene->update(world.layer);
    ASSERT_FALSE(device.scene->has_top_level());
    const Framebuffer after = device.render(world.layer, camera, s);
    matches_cpu("after the ball", after);
    EXPECT_EQ(test::differing_pixels(after, before), 0u)
        << "pixels that differ from the frame before the ball came";
  }
}

// A deforming mesh with sampled normals (Animation::normals, BART's tpa) is shaded with them on
// the device too, frame after frame as they change, and with geometric normals once it has none:
// each frame matches the CPU's, and the normals visibly change the CPU's image.
/// Pixels of which some channel differs by more than 1%.
std::uint32_t differing(const Framebuffer& a, const Framebuffer& b) {
  std::uint32_t n = 0;
  for (std::size_t i = 0; i < a.pixels().size(); ++i) {
    const vec3 d = glm::abs(a.pixels()[i] - b.pixels()[i]);
    n += glm::max(d.x, glm::max(d.y, d.z)) > 0.01f ? 1u : 0u;
  }
  return n;
}

TEST(DeviceFramesScene, AMorphingMeshIsShadedWithItsSampledNormals) {
  SPECULA_NEED_DEVICE();
  ecs::Registry reg;
  test::cornell(reg);
  Material m;
  m.base_color = vec3(0.9f, 0.8f, 0.3f);
  const ecs::Entity blob =
      test::add_mesh(reg, test::primitive("sphere", 0.45f, vec3(1), 8, 4),
                     test::at(vec3(0.0f, 1.0f, 0.5f)), m, Kinematics::Type::Free);
  (void)test::add_point_light(reg, vec3(0.6f, 1.7f, 1.8f), 3.0f); // the panel lights no Whitted ray
  const TriangleMesh& sphere = *reg.get<Mesh>(blob).geometry;
  ASSERT_EQ(sphere.normals.size(), sphere.positions.size());
  std::uint64_t tick = 0;
  // Squashed in y by `f`, with the squashed sphere's normals or none.
  const auto squash = [&](float f, bool normals) {
    Mesh& mesh = reg.get<Mesh>(blob);
    mesh.deformed_positions = sphere.positions;
    for (vec3& p : mesh.deformed_positions) p.y *= f;
    mesh.deformed_normals.clear();
    if (normals)
      for (const vec3& n : sphere.normals)
        mesh.deformed_normals.push_back(glm::normalize(vec3(n.x, n.y / f, n.z)));
    mesh.deformed_tick = ++tick;
  };
  squash(0.5f, true);
  test::TracedWorld world(reg, reference_backend(), test::device_mirror_options());
  const Camera camera = test::cornell_camera();
  const TraceSettings s = settings_for(TraceMode::Whitted);
  Device device(world.layer, gpu::Execution::wavefront);
  const auto frame = [&](const char* what) {
    SCOPED_TRACE(what);
    const Framebuffer image = device.render(world.layer, camera, s);
    Framebuffer cpu(kWidth, kHeight);
    (void)render_frame(*world.tracer, world.layer, camera, s, cpu);
    EXPECT_GE(psnr(cpu, image), 45.0);
    EXPECT_LE(differing(cpu, image), kWidth * kHeight / 500) << "pixels that differ visibly";
    EXPECT_EQ(device.counters.cut, 0u);
    return cpu;
  };
  (void)frame("first frame, normals of y * 0.5");
  for (const auto& [f, normals, what] :
       {std::tuple{1.5f, true, "normals of y * 1.5"}, std::tuple{1.5f, false, "face normals"},
        std::tuple{1.5f, true, "normals again"}}) {
    squash(f, normals);
    world.update(reg);
    device.scene->update(world.layer);
    const Framebuffer cpu = frame(what);
    if (!normals) {
      squash(1.5f, true);
      world.update(reg);
      device.scene->update(world.layer);
      Framebuffer smooth(kWidth, kHeight);
      (void)render_frame(*world.tracer, world.layer, camera, s, smooth);
      // Far more than a device frame may differ by: a device shading with face normals (or
      // stale ones) fails.
      EXPECT_GE(differing(cpu, smooth), kWidth * kHeight / 50)
          << "smooth and faceted shading look alike";
    }
  }
}

// Timestamps after each stage's dispatches: a wavefront frame's eye, trace, shade, shadow and
// fold stages each take time and together make the frame's device time (hybrid mode's
// visibility stage none here); the single kernel has no stages.
TEST(DeviceFramesScene, EachWavefrontStagesTimeAddsUpToTheFramesDeviceTime) {
  SPECULA_NEED_DEVICE();
  const CornellBox box(TraceMode::Whitted);
  const test::TracedWorld& world = box.world;
  const Camera& camera = box.camera;
  const TraceSettings& s = box.settings;
  Device wavefront(world.layer, gpu::Execution::wavefront);
  (void)wavefront.render(world.layer, camera, s);
  const gpu::GpuTraceCounters& c = wavefront.counters;
  if (!wavefront.context->info().timestamps) {
    EXPECT_EQ(c.stage_ms, GpuStageTimes{}) << "no timestamps, no stage times";
    GTEST_SKIP() << "the device has no timestamp queries";
  }
  double sum = 0.0;
  for (int k = 0; k < kGpuStageCount; ++k) {
    const double ms = c.stage_ms[std::size_t(k)];
    SCOPED_TRACE(gpu_stage_name(GpuStage(k)));
    if (GpuStage(k) == GpuStage::Visibility)
      EXPECT_EQ(ms, 0.0);
    else
      EXPECT_GT(ms, 0.0);
    sum += ms;
  }
  EXPECT_LE(sum, c.gpu_ms * (1.0 + 1e-9));
  EXPECT_GE(sum, 0.95 * c.gpu_ms) << "the stages cover the frame's dispatches";
  Device single(world.layer, gpu::Execution::single_kernel);
  (void)single.render(world.layer, camera, s);
  EXPECT_GT(single.counters.gpu_ms, 0.0);
  EXPECT_EQ(single.counters.stage_ms, GpuStageTimes{});
}

TEST(DeviceFramesScene, FactoryBackendRendersOnTheDevice) {
  SPECULA_NEED_DEVICE();
  ecs::Registry reg;
  test::cornell(reg);
  test::TracedWorld world(reg, "vulkan");
  const auto& vk = dynamic_cast<const gpu::VulkanTracer&>(*world.tracer);
  Framebuffer image(kWidth, kHeight);
  const FrameStats stats =
      render_frame(*world.tracer, world.layer, test::cornell_camera(),
                   settings_for(TraceMode::Whitted), image);
  EXPECT_EQ(stats.rays[RayKind::Primary], std::uint64_t(kWidth) * kHeight);
  EXPECT_GT(vk.counters().dispatches, 0u);
  EXPECT_EQ(vk.counters().cut, 0u);
  // The frame's stats carry the device's counters (the stats file's frames[].gpu).
  EXPECT_TRUE(stats.gpu.present);
  EXPECT_EQ(stats.gpu.rays, stats.rays.total());
  EXPECT_EQ(stats.gpu.dispatches, vk.counters().dispatches);
  EXPECT_EQ(stats.gpu.cut, 0u);
}

TEST(DeviceFramesScene, DeviceLossIsAClearError) {
  SPECULA_NEED_DEVICE();
  ecs::Registry reg;
  test::cornell(reg);
  test::TracedWorld world(reg, reference_backend(), test::device_mirror_options());
  Device device(world.layer, gpu::Execution::wavefront);
  device.context->simulate_device_loss();
  try {
    (void)device.render(world.layer, test::cornell_camera(), settings_for(TraceMode::Whitted));
    FAIL() << "expected GpuError";
  } catch (const gpu::GpuError& e) {
    EXPECT_TRUE(e.device_lost());
    EXPECT_NE(std::string(e.what()).find("device frame"), std::string::npos) << e.what();
  }
}

} // namespace
} // namespace specula
