// Path and shadow frames on the device (engine/gpu/device_path.h) against the CPU integrators on
// native-bvh (the structure the device traverses, hit for hit): the device sampler's points equal
// trace/sampler.h's bit for bit; with the same seed and sample indices the images agree per pixel
// (differences come only from cos/sin in the cosine-weighted direction, whose last bits differ
// between lavapipe and libm); the means over frames of both
// converge to the same reference; shadow frames match; resumption after a small budget gives
// the same image; no ray is cut by the driver.
#include "device_scenes.h"
#include "specula/core/error.h"
#include "specula/gpu/device_renderer.h"
#include "specula/gpu/device_path.h"
#include "specula/gpu/gpu_scene.h"
#include "specula/gpu/shaders.h"
#include "specula/gpu/vulkan_tracer.h"
#include "specula/image/denoise.h"
#include "specula/image/metrics.h"
#include "specula/render/render_job.h"
#include "specula/systems/schedule.h"
#include "specula/trace/render_frame.h"
#include "specula/trace/sampler.h"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <random>

namespace specula {
namespace {

constexpr std::uint32_t kWidth = 64, kHeight = 48;

struct Device {
  std::unique_ptr<gpu::Context> context;
  std::unique_ptr<gpu::GpuScene> scene;
  std::unique_ptr<gpu::DeviceRenderer> renderer;
  gpu::GpuTraceCounters counters;
  FrameStats stats;

  explicit Device(const SceneLayer& layer,
                  gpu::Execution execution = gpu::Execution::wavefront,
                  gpu::GpuStructure structure = gpu::GpuStructure::bvh) {
    context = gpu::Context::create();
    scene = std::make_unique<gpu::GpuScene>(*context, structure);
    scene->update(layer);
    renderer = std::make_unique<gpu::DeviceRenderer>(*context, *scene, execution);
  }
  Framebuffer render(const SceneLayer& layer, const TraceSettings& s) {
    Framebuffer out(kWidth, kHeight);
    renderer->render(layer, test::cornell_camera(), s, out, stats, counters);
    return out;
  }
};

struct Cpu {
  ecs::Registry reg;
  std::unique_ptr<test::TracedWorld> world;
  Cpu() {
    test::cornell(reg);
    world = std::make_unique<test::TracedWorld>(reg, "native-bvh", test::device_mirror_options());
  }
  Framebuffer render(const TraceSettings& s, FrameStats* stats = nullptr) {
    Framebuffer out(kWidth, kHeight);
    const FrameStats f = render_frame(*world->tracer, world->layer, test::cornell_camera(), s, out);
    if (stats != nullptr) *stats = f;
    return out;
  }
};

TraceSettings path_settings(std::uint32_t spp, std::uint32_t offset) {
  TraceSettings s;
  s.mode = TraceMode::Path;
  s.max_depth = 5;
  s.threads = 2;
  s.spp = spp;
  s.seed = 7;
  s.sample_offset = offset;
  return s;
}

/// A shadow frame with `samples` area-light samples per pixel.
TraceSettings shadow_settings(std::uint32_t samples) {
  TraceSettings s;
  s.mode = TraceMode::Shadow;
  s.threads = 2;
  s.shadow_samples = samples;
  s.seed = 11;
  return s;
}

/// Mean of frames [0, k) of `spp` samples each, frame f at sample offset f·spp.
template <class Render>
Framebuffer mean_of_frames(Render&& render, std::uint32_t k, std::uint32_t spp) {
  Framebuffer sum(kWidth, kHeight);
  for (std::uint32_t f = 0; f < k; ++f) {
    const Framebuffer frame = render(path_settings(spp, f * spp));
    for (std::size_t i = 0; i < sum.pixels().size(); ++i) sum.pixels()[i] += frame.pixels()[i];
  }
  for (vec3& p : sum.pixels()) p /= float(k);
  return sum;
}

/// Fraction of pixels whose values are bit-identical.
double identical(const Framebuffer& a, const Framebuffer& b) {
  return 1.0 - double(test::differing_pixels(a, b)) / double(a.pixels().size());
}

TEST(DevicePath, SamplerPointsEqualTheCpuBitForBit) {
  SPECULA_NEED_DEVICE();
  auto ctx = gpu::Context::create();
  constexpr std::uint32_t kQueries = 4096;
  std::mt19937 rng(20261124);
  std::vector<glm::uvec4> queries(kQueries);
  for (glm::uvec4& q : queries) q = glm::uvec4(rng() % 100000, rng(), rng(), rng() % 32);
  queries[0] = glm::uvec4(0, 0, 0, 0); // the first point of the first pixel
  queries[1] = glm::uvec4(5, 0, 0xFFFFFFFFu, 31);
  gpu::Buffer tables = ctx->make_buffer(sizeof(sobol_detail::kByteTables));
  tables.upload(sobol_detail::kByteTables.data(), sizeof(sobol_detail::kByteTables));
  gpu::Buffer in = ctx->make_buffer(kQueries * 16), out = ctx->make_buffer(kQueries * 16);
  in.upload(queries.data(), kQueries * 16);
  const gpu::Pipeline pipeline = ctx->make_pipeline(
      {gpu::shader_spirv("sampler_points"), 3, sizeof(std::uint32_t), {}, "sampler_points"});
  gpu::Commands cmd(*ctx);
  const std::uint32_t count = kQueries;
  cmd.dispatch(pipeline, {&tables, &in, &out}, &count, (kQueries + 63) / 64);
  cmd.submit();
  std::vector<glm::uvec4> points(kQueries);
  out.download(points.data(), kQueries * 16);
  std::uint32_t differ = 0;
  for (std::uint32_t i = 0; i < kQueries; ++i) {
    const glm::uvec4 q = queries[i];
    const std::uint32_t set_seed = hash_combine(hash_combine(hash_u32(q.y), q.x), q.w);
    const std::uint32_t shuffled = sobol_detail::owen_scramble(q.z, set_seed);
    const vec4 cpu = PixelSampler(q.x, q.y).get4(q.z, q.w);
    for (std::uint32_t d = 0; d < 4; ++d) {
      const std::uint32_t bits =
          sobol_detail::owen_scramble(sobol_u32(shuffled, d), hash_combine(set_seed, d + 1));
      // The bits the CPU's own sampler turns into this float.
      ASSERT_EQ(to_unit_float(bits), cpu[int(d)]);
      differ += points[i][int(d)] != bits ? 1u : 0u;
    }
  }
  EXPECT_EQ(differ, 0u) << "of " << 4 * kQueries << " dimensions";
}

TEST(DevicePath, PathFrameMatchesTheCpuPerPixel) {
  SPECULA_NEED_DEVICE();
  Cpu cpu;
  Device device(cpu.world->layer);
  for (const LightSampling sampling : {LightSampling::Mis, LightSampling::Bsdf, LightSampling::Light}) {
    TraceSettings s = path_settings(1, 3);
    s.sampling = sampling;
    FrameStats cpu_stats;
    const Framebuffer a = cpu.render(s, &cpu_stats);
    const Framebuffer b = device.render(cpu.world->layer, s);
    const double p = psnr(a, b);
    std::cout << "path " << light_sampling_name(sampling) << " 1 spp: PSNR " << p
              << " dB, identical pixels " << 100.0 * identical(a, b) << "%, rays "
              << device.counters.rays << " (CPU " << cpu_stats.rays.total() << ")\n";
    // Measured 144 dB, 91.5% of pixels bit-identical: the rest differ in their last bits (cos
    // and sin's), not by a path sent elsewhere.
    EXPECT_GE(p, 100.0);
    EXPECT_GE(identical(a, b), 0.85);
    EXPECT_EQ(device.stats.rays[RayKind::Primary], cpu_stats.rays[RayKind::Primary]);
    EXPECT_EQ(device.counters.cut, 0u);
  }
}

TEST(DevicePath, MeansOverFramesConvergeToTheSameReference) {
  SPECULA_NEED_DEVICE();
  Cpu cpu;
  Device device(cpu.world->layer);
  constexpr std::uint32_t kSpp = 2;
  // The reference: the CPU's mean over far more samples (a disjoint part of the sequences); half
  // as many in builds with assertions (the asan preset, where this CPU frame dominates the test).
#ifdef NDEBUG
  constexpr std::uint32_t kReferenceSpp = 256;
#else
  constexpr std::uint32_t kReferenceSpp = 128;
#endif
  const Framebuffer reference = cpu.render(path_settings(kReferenceSpp, 1u << 16));
  const auto on_cpu = [&](const TraceSettings& s) { return cpu.render(s); };
  const auto on_device = [&](const TraceSettings& s) {
    Framebuffer f = device.render(cpu.world->layer, s);
    EXPECT_EQ(device.counters.cut, 0u);
    return f;
  };
  const double cpu1 = rmse(mean_of_frames(on_cpu, 1, kSpp), reference);
  const double gpu1 = rmse(mean_of_frames(on_device, 1, kSpp), reference);
  const Framebuffer cpu_k = mean_of_frames(on_cpu, 8, kSpp);
  const Framebuffer gpu_k = mean_of_frames(on_device, 8, kSpp);
  const double cpu8 = rmse(cpu_k, reference), gpu8 = rmse(gpu_k, reference);
  std::cout << "RMSE to the reference, 1 frame: CPU " << cpu1 << ", device " << gpu1
            << "; 8 frames: CPU " << cpu8 << ", device " << gpu8 << "; CPU vs device after 8: PSNR "
            << psnr(cpu_k, gpu_k) << " dB\n";
  EXPECT_LT(gpu8, 0.6 * gpu1); // error shrinks (1/√8 ≈ 0.35 for pure noise)
  EXPECT_LT(cpu8, 0.6 * cpu1);
  EXPECT_NEAR(gpu8, cpu8, 0.1 * cpu8);
  EXPECT_GE(psnr(cpu_k, gpu_k), 100.0); // measured 151 dB
}

TEST(DevicePath, ShadowFramesMatchTheCpu) {
  SPECULA_NEED_DEVICE();
  Cpu cpu;
  Device device(cpu.world->layer);
  for (const std::uint32_t samples : {0u, 4u}) { // 0: the point light alone
    TraceSettings s = shadow_settings(samples);
    s.sample_offset = 8;
    FrameStats cpu_stats;
    const Framebuffer a = cpu.render(s, &cpu_stats);
    const Framebuffer b = device.render(cpu.world->layer, s);
    std::cout << "shadow, " << samples << " area samples: PSNR " << psnr(a, b)
              << " dB, identical pixels " << 100.0 * identical(a, b) << "%\n";
    // Integer sample points, the Whitted kernels' exact shading, and no transcendentals (sqrt and
    // division round as on the CPU): bit-identical, measured.
    EXPECT_EQ(identical(a, b), 1.0);
    EXPECT_EQ(device.stats.rays.total(), cpu_stats.rays.total());
    EXPECT_EQ(device.counters.cut, 0u);
  }
}

// A budget far below a ray's walk: rays stop mid-walk, save their traversal state and go on in
// the next pass, so path and shadow frames come out as with the full budget (same pixels, same
// rays), none cut by the driver and none started over for want of a pool slot.
TEST(DevicePath, SmallBudgetResumesToTheSameImage) {
  SPECULA_NEED_DEVICE();
  Cpu cpu;
  Device full(cpu.world->layer), small(cpu.world->layer);
  small.renderer->set_budget(16);
  const TraceSettings shadow = shadow_settings(2);
  for (const TraceSettings& s : {path_settings(1, 0), shadow}) {
    const Framebuffer a = full.render(cpu.world->layer, s);
    const Framebuffer b = small.render(cpu.world->layer, s);
    EXPECT_EQ(full.counters.resumed, 0u);
    // Traces stopped mid-walk and the frame still finished: started over from the root, a
    // wavefront ray needing more than 16 steps never would (the frame used to end in an error).
    EXPECT_GT(small.counters.resumed, 0u);
    EXPECT_EQ(small.counters.restarted, 0u);
    EXPECT_EQ(small.counters.cut, 0u);
    EXPECT_EQ(full.counters.rays, small.counters.rays);
    EXPECT_EQ(identical(a, b), 1.0);
  }
}

// The single kernel (path_single.comp) walks each path in one invocation with the wavefront's
// shading and gather, so its path and shadow frames are the wavefront's bit for bit, on both
// structures, with several samples per pixel (batches) and with a budget so small that nearly
// every trace stops mid-walk and goes on in a later dispatch from its own pool slot.
TEST(DevicePath, SingleKernelFramesEqualTheWavefrontsBitForBit) {
  SPECULA_NEED_DEVICE();
  Cpu cpu;
  const TraceSettings shadow = shadow_settings(4);
  TraceSettings bsdf = path_settings(3, 5);
  bsdf.sampling = LightSampling::Bsdf;
  auto context = gpu::Context::create();
  for (const gpu::GpuStructure structure : {gpu::GpuStructure::bvh, gpu::GpuStructure::grid}) {
    gpu::GpuScene scene(*context, structure);
    scene.update(cpu.world->layer);
    gpu::DeviceRenderer wavefront(*context, scene, gpu::Execution::wavefront);
    gpu::DeviceRenderer single(*context, scene, gpu::Execution::single_kernel);
    gpu::DeviceRenderer small(*context, scene, gpu::Execution::single_kernel);
    small.set_budget(16);
    struct Run {
      Framebuffer image{kWidth, kHeight};
      FrameStats stats;
      gpu::GpuTraceCounters counters;
    };
    const auto render = [&](gpu::DeviceRenderer& r, const TraceSettings& s) {
      Run run;
      r.render(cpu.world->layer, test::cornell_camera(), s, run.image, run.stats, run.counters);
      return run;
    };
    for (const TraceSettings& s : {path_settings(1, 0), bsdf, shadow}) {
      ASSERT_TRUE(single.supports(s, nullptr, false));
      const Run a = render(wavefront, s), b = render(single, s), c = render(small, s);
      std::cout << trace_mode_name(s.mode) << " " << s.spp << " spp, "
                << (structure == gpu::GpuStructure::bvh ? "bvh" : "grid")
                << ": single kernel identical pixels " << 100.0 * identical(a.image, b.image)
                << "%, budget 16 " << 100.0 * identical(a.image, c.image) << "% ("
                << c.counters.resumed << " resumed, " << c.counters.dispatches << " dispatches)\n";
      EXPECT_EQ(identical(a.image, b.image), 1.0);
      EXPECT_EQ(identical(a.image, c.image), 1.0);
      for (int k = 0; k < kRayKindCount; ++k) {
        EXPECT_EQ(a.stats.rays.count[k], b.stats.rays.count[k]) << "kind " << k;
        EXPECT_EQ(a.stats.rays.count[k], c.stats.rays.count[k]) << "kind " << k;
      }
      EXPECT_EQ(b.counters.cut, 0u);
      EXPECT_EQ(c.counters.cut, 0u);
      EXPECT_GT(c.counters.resumed, 0u); // walks did stop and go on
      EXPECT_EQ(c.counters.restarted, 0u);
    }
  }
}

// The denoiser's guides come from each pixel's first primary hit, as the CPU integrators write
// them (integrators.h's write_guide): albedo, shading normal and distance equal bit for bit, in
// path and shadow frames and both execution styles. Whitted frames have no guides on the device.
TEST(DevicePath, GuidesEqualTheCpusBitForBit) {
  SPECULA_NEED_DEVICE();
  Cpu cpu;
  const TraceSettings shadow = shadow_settings(2);
  TraceSettings whitted;
  whitted.mode = TraceMode::Whitted;
  auto context = gpu::Context::create();
  gpu::GpuScene scene(*context, gpu::GpuStructure::bvh);
  scene.update(cpu.world->layer);
  for (const gpu::Execution e : {gpu::Execution::wavefront, gpu::Execution::single_kernel}) {
    gpu::DeviceRenderer renderer(*context, scene, e);
    EXPECT_FALSE(renderer.supports(whitted, nullptr, true));
    EXPECT_TRUE(renderer.supports(whitted, nullptr, false));
    for (const TraceSettings& s : {path_settings(2, 0), shadow}) {
      ASSERT_TRUE(renderer.supports(s, nullptr, true));
      GuideBuffers a, b;
      Framebuffer ca(kWidth, kHeight), cb(kWidth, kHeight);
      (void)render_frame(*cpu.world->tracer, cpu.world->layer, test::cornell_camera(), s, ca,
                         nullptr, &a);
      FrameStats stats;
      gpu::GpuTraceCounters counters;
      renderer.render(cpu.world->layer, test::cornell_camera(), s, cb, stats, counters, nullptr,
                      &b);
      ASSERT_EQ(b.size(), a.size());
      std::size_t albedo = 0, normal = 0, depth = 0, hits = 0;
      for (std::size_t i = 0; i < a.size(); ++i) {
        albedo += a.albedo[i] == b.albedo[i];
        normal += a.normal[i] == b.normal[i];
        depth += a.depth[i] == b.depth[i];
        hits += std::isfinite(a.depth[i]) ? 1u : 0u;
      }
      std::cout << trace_mode_name(s.mode) << ", " << (e == gpu::Execution::wavefront ? "wavefront" : "single")
                << ": equal albedo " << albedo << ", normal " << normal << ", depth " << depth
                << " of " << a.size() << " pixels (" << hits << " hits)\n";
      EXPECT_GT(hits, a.size() / 2);
      EXPECT_EQ(albedo, a.size());
      EXPECT_EQ(normal, a.size());
      EXPECT_EQ(depth, a.size());
    }
  }
}

// `--backend vulkan --mode path --denoise` through the schedule: the frames run on the device
// (they fell back to the CPU integrators while the device wrote no guides), and the denoised
// images equal native-bvh's up to the last bits of the few paths cos/sin send elsewhere. (With
// the job's default 16-wide CPU packets, whose primary hits round some bits differently from
// single rays, more paths part ways: 43-48 dB, measured.)
TEST(DevicePath, ADenoisedPathJobRendersOnTheDevice) {
  SPECULA_NEED_DEVICE();
  std::vector<Framebuffer> images[2], noisy[2];
  bool on_device = true;
  for (int k = 0; k < 2; ++k) {
    ecs::Registry reg;
    test::cornell(reg);
    const Camera c = test::cornell_camera();
    test::add_camera(reg, vec3(c.position), vec3(c.look_at), glm::degrees(c.vertical_fov));
    RenderJob job;
    job.backend = k == 0 ? "native-bvh" : "vulkan";
    job.native_wide_bvh = false; // the device's mirror (test::device_mirror_options)
    job.settings = path_settings(1, 0);
    job.packet_width = 1; // as the per-pixel tests: wider CPU packets round some hits otherwise
    job.image = Framebuffer(kWidth, kHeight);
    job.denoise = DenoiseSettings{};
    prepare_rendering(reg, std::move(job));
    Schedule schedule;
    for (int f = 0; f < 3; ++f) {
      schedule.tick(reg, 1.0 / 60.0);
      const RenderJob& done = reg.resource<RenderJob>();
      images[k].push_back(done.image);
      noisy[k].push_back(done.noisy_image());
      if (k == 1) on_device = on_device && done.last.gpu.present;
      EXPECT_EQ(done.guides.size(), std::size_t(kWidth) * kHeight);
    }
  }
  EXPECT_TRUE(on_device) << "a denoised vulkan path frame ran on the CPU integrators";
  for (std::size_t f = 0; f < images[0].size(); ++f) {
    const double p = psnr(images[0][f], images[1][f]);
    std::cout << "denoised frame " << f << ": PSNR vulkan vs native-bvh " << p << " dB (noisy "
              << psnr(noisy[0][f], noisy[1][f]) << " dB)\n";
    EXPECT_GE(p, 100.0) << "frame " << f; // measured 136-143 dB
  }
}

// path_shade draws a pixel's area-light samples in one loop: more than lavapipe's loop cap allows
// a SIMD vector would be cut silently, so such frames stay on the CPU.
TEST(DevicePath, ShadowFramesBeyondTheSampleLoopBoundRunOnTheCpu) {
  SPECULA_NEED_DEVICE();
  auto ctx = gpu::Context::create();
  gpu::GpuScene scene(*ctx, gpu::GpuStructure::bvh);
  const gpu::DeviceRenderer wavefront(*ctx, scene, gpu::Execution::wavefront);
  TraceSettings s;
  s.mode = TraceMode::Shadow;
  s.shadow_samples = gpu::DevicePath::kMaxShadowSamples;
  EXPECT_TRUE(wavefront.supports(s, nullptr, false));
  s.shadow_samples = gpu::DevicePath::kMaxShadowSamples + 1;
  EXPECT_FALSE(wavefront.supports(s, nullptr, false));
}

} // namespace
} // namespace specula
