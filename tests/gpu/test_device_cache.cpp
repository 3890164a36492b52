// Ray-cache cubes on the device (engine/gpu/device_cache.h): the device's cube addressing is
// cube_map.h's bit for bit; cached Whitted frames (direction, tau and march modes, wavefront and
// single kernel) equal the CPU integrator's over native-bvh — image and the store's counters —
// frame after frame while the cubes fill, and again after an object moves and the store
// invalidates; no ray is cut by the driver; the kernels count lookups and served rays as the
// store does, and, where every ray is recorded, every device lookup agrees with the store's own.
#include "device_scenes.h"
#include "specula/cache/cube_map.h"
#include "specula/cache/ray_cache.h"
#include "specula/core/error.h"
#include "specula/gpu/device_cache.h"
#include "specula/gpu/device_renderer.h"
#include "specula/gpu/gpu_scene.h"
#include "specula/gpu/shaders.h"
#include "specula/gpu/vulkan_tracer.h"
#include "specula/image/metrics.h"
#include "specula/render/render_job.h"
#include "specula/scene/components/ray_cache_cube.h"
#include "specula/systems/schedule.h"
#include "specula/trace/render_frame.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <iostream>
#include <random>

namespace specula {
namespace {

using cache::CachePolicy;
using cache::CacheSettings;
using cache::LookupMode;
using cache::RayCacheStore;

/// Directions that probe cube_coord's branches: the axes, face edges and corners (ties between
/// axes), signed zeros, texel boundaries on every face (u·res exactly an integer), and seeded
/// random ones of random length.
std::vector<vec3> probe_directions(std::uint32_t resolution) {
  std::vector<vec3> d;
  for (int axis = 0; axis < 3; ++axis)
    for (const float s : {1.0f, -1.0f, 0.25f, -3.0f}) {
      vec3 v(0.0f);
      v[axis] = s;
      d.push_back(v);
      v[(axis + 1) % 3] = -0.0f;
      d.push_back(v);
    }
  for (const float a : {1.0f, -1.0f})
    for (const float b : {1.0f, -1.0f})
      for (const float c : {1.0f, -1.0f, 0.5f, -0.5f, 0.0f}) {
        d.emplace_back(a, b, c); // x = y ties
        d.emplace_back(c, a, b); // y = z ties
        d.emplace_back(a, c, b); // x = z ties
      }
  for (std::uint32_t face = 0; face < cache::kFaceCount; ++face)
    for (std::uint32_t i = 0; i <= resolution; ++i)
      for (std::uint32_t j = 0; j <= resolution; j += std::max(1u, resolution / 8))
        d.push_back(cache::cube_direction(face, float(i) / float(resolution),
                                          float(j) / float(resolution)));
  std::mt19937 rng(1234u + resolution);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f), scale(0.01f, 100.0f);
  while (d.size() < 4096) {
    const vec3 v(u(rng), u(rng), u(rng));
    if (glm::dot(v, v) > 0.0f) d.push_back(v * scale(rng));
  }
  return d;
}

TEST(DeviceCache, CubeAddressingMatchesCubeMapBitForBit) {
  SPECULA_NEED_DEVICE();
  auto ctx = gpu::Context::create();
  gpu::Pipeline pipeline = ctx->make_pipeline(
      {gpu::shader_spirv("cube_address"), 2, 2 * sizeof(std::uint32_t), {}, "cube_address"});
  for (const std::uint32_t res : {1u, 5u, 32u, 64u}) {
    const std::vector<vec3> dirs = probe_directions(res);
    std::vector<vec4> in(dirs.size());
    for (std::size_t i = 0; i < dirs.size(); ++i) in[i] = vec4(dirs[i], 0.0f);
    gpu::Buffer input = ctx->make_buffer(in.size() * sizeof(vec4));
    gpu::Buffer output = ctx->make_buffer(in.size() * 2 * sizeof(std::uint32_t));
    input.upload(in.data(), in.size() * sizeof(vec4));
    const std::uint32_t push[2] = {std::uint32_t(in.size()), res};
    gpu::Commands cmd(*ctx, 1);
    cmd.dispatch(pipeline, {&input, &output}, push, (std::uint32_t(in.size()) + 63) / 64);
    cmd.submit();
    std::vector<std::uint32_t> out(in.size() * 2);
    output.download(out.data(), out.size() * sizeof(std::uint32_t));
    std::size_t differ = 0;
    for (std::size_t i = 0; i < dirs.size(); ++i) {
      const cache::CubeCoord c = cache::cube_coord(dirs[i]);
      const std::uint32_t texel = cache::texel_index(c, res);
      if (out[2 * i] != c.face || out[2 * i + 1] != texel) {
        if (++differ <= 5)
          ADD_FAILURE() << "res " << res << " direction (" << dirs[i].x << ", " << dirs[i].y << ", "
                        << dirs[i].z << "): device face " << out[2 * i] << " texel "
                        << out[2 * i + 1] << ", CPU face " << c.face << " texel " << texel;
      }
    }
    EXPECT_EQ(differ, 0u) << "of " << dirs.size() << " directions at resolution " << res;
  }
}

constexpr std::uint32_t kSize = 40;

Material mirror(float reflectivity) {
  Material m;
  m.base_color = vec3(0.9f);
  m.reflectivity = reflectivity;
  return m;
}

Material diffuse(const vec3& c) {
  Material m;
  m.base_color = c;
  return m;
}

/// Two cached mirror spheres that see each other (nested leaving rays), a glass sphere with a
/// cube (exiting refractions), a diffuse sphere that moves, a ground and a light.
struct CacheScene {
  ecs::Registry reg;
  ecs::Entity mover;
  Camera camera;

  CacheScene() {
    using test::add_mesh;
    using test::at;
    using test::primitive;
    const ecs::Entity a = add_mesh(reg, primitive("sphere", 1.0f, vec3(1), 16, 8),
                                   at(vec3(-1.1f, 1, 0)), mirror(0.9f));
    const ecs::Entity b = add_mesh(reg, primitive("sphere", 0.7f, vec3(1), 16, 8),
                                   at(vec3(1.2f, 0.7f, 0.3f)), mirror(0.6f));
    Material glass;
    glass.base_color = vec3(1.0f);
    glass.transmission = 0.9f;
    glass.ior = 1.5f;
    const ecs::Entity c =
        add_mesh(reg, primitive("sphere", 0.5f, vec3(1), 12, 6), at(vec3(0.2f, 0.5f, 1.4f)), glass);
    for (const ecs::Entity e : {a, b, c}) reg.emplace<RayCacheCube>(e, RayCacheCube{16});
    mover = add_mesh(reg, primitive("sphere", 0.4f, vec3(1), 12, 6), at(vec3(0.1f, 0.4f, -1.2f)),
                     diffuse(vec3(0.9f, 0.3f, 0.2f)), Kinematics::Type::Free);
    add_mesh(reg, primitive("plane", 1, vec3(8.0f)), at(vec3(0)), diffuse(vec3(0.6f, 0.65f, 0.7f)));
    test::add_point_light(reg, vec3(1.5f, 4.0f, 2.5f), 40.0f);
    camera.position = dvec3(0.3, 1.6, 5.0);
    camera.look_at = dvec3(0, 0.7, 0);
    camera.vertical_fov = glm::radians(45.0f);
  }
};

struct Param {
  LookupMode mode;
  gpu::Execution execution;
  CachePolicy policy = CachePolicy::On;
  /// every: each leaving ray recorded and its lookup replayed on the host, which checks the
  /// device's answers and counts; changes (the default): only rays that may change the store.
  gpu::DeviceCache::Records records = gpu::DeviceCache::Records::changes;
  /// Wavefront frames in chunks of at most this many pixels (0: in one piece): the lookups,
  /// counts and records of every chunk reach the store as those of one frame.
  std::uint32_t chunk = 0;
};

class DeviceCacheFrames : public ::testing::TestWithParam<Param> {};

/// Renders `frames` frames on the CPU (native-bvh) and on the device, each with its own store of
/// the same settings, moving the mover before frame `move_at`; checks each frame. `budget`: the
/// device's traversal budget (0: the default). `orbit`: degrees the camera turns about the scene
/// per frame. Returns the frames the device rendered (all of them: every lookup mode runs on the
/// device; the check is kept for a store it would refuse).
int compare_frames(const Param& p, int frames, int move_at, std::uint32_t budget = 0,
                   float orbit = 0.0f) {
  CacheScene scene;
  test::TracedWorld world(scene.reg, "native-bvh", test::device_mirror_options());
  CacheSettings cs;
  cs.policy = p.policy;
  cs.lookup = p.mode;
  cs.tau_deg = 1.0f;
  RayCacheStore cpu_store(cs), device_store(cs);
  auto context = gpu::Context::create();
  gpu::GpuScene gpu_scene(*context, gpu::GpuStructure::bvh);
  gpu_scene.update(world.layer);
  gpu::DeviceRenderer renderer(*context, gpu_scene, p.execution);
  renderer.cache().set_records(p.records);
  renderer.set_chunk_limit(p.chunk);
  if (budget > 0) renderer.set_budget(budget);
  TraceSettings s;
  s.mode = TraceMode::Whitted;
  s.max_depth = 4;
  s.threads = 2;
  s.background = vec3(0.1f, 0.15f, 0.3f);
  EXPECT_TRUE(renderer.supports(s, &device_store, false));
  std::uint64_t hits = 0, verified = 0;
  int on_device = 0;
  const Camera start = scene.camera;
  for (int f = 0; f < frames; ++f) {
    if (orbit != 0.0f) {
      const double a = glm::radians(double(orbit) * f);
      const dvec3 c = start.look_at, d = start.position - c;
      scene.camera.position =
          c + dvec3(d.x * std::cos(a) + d.z * std::sin(a), d.y, -d.x * std::sin(a) + d.z * std::cos(a));
    }
    // A tick: the layer synced (its delta: what changed since the last frame), then the cubes
    // invalidated from it, as the schedule runs them.
    if (f == move_at)
      scene.reg.patch<Transform>(scene.mover, [](Transform& t) { t.translation.x += 0.8f; });
    if (f > 0) {
      world.update(scene.reg);
      gpu_scene.update(world.layer);
    }
    const cache::InvalidationStats ci = cpu_store.invalidate(scene.reg, world.layer);
    const cache::InvalidationStats di = device_store.invalidate(scene.reg, world.layer);
    EXPECT_EQ(ci.outdated, di.outdated);
    if (f == move_at) {
      EXPECT_GT(di.outdated, 0u) << "the move outdated nothing: no test of it";
    }
    // What the device copy must hold for this frame: the store's texels after invalidation.
    std::vector<cache::Texel> before;
    for (std::size_t c = 0; c < device_store.cube_count(); ++c) {
      const auto t = device_store.cube(c).texels;
      before.insert(before.end(), t.begin(), t.end());
    }
    Framebuffer cpu(kSize, kSize), device(kSize, kSize);
    (void)render_frame(*world.tracer, world.layer, scene.camera, s, cpu, &cpu_store);
    FrameStats stats;
    gpu::GpuTraceCounters counters;
    const bool device_frame = renderer.supports(s, &device_store, false);
    if (device_frame) {
      renderer.render(world.layer, scene.camera, s, device, stats, counters, &device_store);
      ++on_device;
      if (p.chunk > 0 && p.execution == gpu::Execution::wavefront) {
        EXPECT_GT(renderer.wave_chunks(), 1u) << "a frame in one piece: no test of chunks";
      }
    } else {
      (void)render_frame(*world.tracer, world.layer, scene.camera, s, device, &device_store);
    }
    const std::size_t differ = test::differing_pixels(cpu, device);
    const CacheCounts& a = cpu_store.counts();
    const CacheCounts& b = device_store.counts();
    std::cout << "frame " << f << ": " << differ << " pixels differ, PSNR " << psnr(cpu, device)
              << " dB; lookups " << b.lookups << " (CPU " << a.lookups << "), hits " << b.hits
              << " (" << a.hits << "), written " << b.written << " (" << a.written << "), valid "
              << b.valid << " (" << a.valid << "), records " << renderer.cache_records()
              << ", texels uploaded " << renderer.cache_texels_uploaded() << "\n";
    EXPECT_EQ(differ, 0u) << "frame " << f;
    if (device_frame && device_store.wants_leaving()) {
      // Uploaded whole or only the texels that changed, the device copy equals the store's.
      std::vector<cache::Texel> copy(before.size());
      renderer.cache().texels().download(copy.data(), copy.size() * sizeof(cache::Texel));
      EXPECT_TRUE(std::memcmp(copy.data(), before.data(), copy.size() * sizeof(cache::Texel)) == 0)
          << "frame " << f << ": the device's texels are not the store's";
    }
    if (device_frame) {
      EXPECT_EQ(counters.cut, 0u);
      EXPECT_EQ(counters.restarted, 0u);
      if (budget > 0) {
        EXPECT_GT(counters.resumed, 0u) << "no trace stopped mid-walk: no test of resumption";
      }
      EXPECT_EQ(renderer.cache_mismatches(), 0u) << "device lookups the store answers otherwise";
      if (p.records == gpu::DeviceCache::Records::every) {
        if (device_store.wants_leaving()) {
          EXPECT_GT(renderer.cache_records(), 0u);
        }
      } else {
        // Only writes (a traced ray onto an outdated texel: the first of each texel is written)
        // and verified rays are recorded.
        EXPECT_GE(renderer.cache_records(), b.written + b.verified) << "frame " << f;
        EXPECT_EQ(renderer.cache_records() == 0, b.written == 0 && b.verified == 0)
            << "frame " << f;
      }
    }
    EXPECT_EQ(b.lookups, a.lookups) << "frame " << f;
    EXPECT_EQ(b.hits, a.hits) << "frame " << f;
    EXPECT_EQ(b.rejected, a.rejected) << "frame " << f;
    EXPECT_EQ(b.written, a.written) << "frame " << f;
    EXPECT_EQ(b.valid, a.valid) << "frame " << f;
    EXPECT_EQ(b.verified, a.verified) << "frame " << f;
    // Auto decides alike: the same modes, for the same reasons, from the same error estimates.
    EXPECT_EQ(b.cubes.size(), a.cubes.size());
    for (std::size_t c = 0; c < std::min(a.cubes.size(), b.cubes.size()); ++c) {
      EXPECT_EQ(b.cubes[c].mode, a.cubes[c].mode) << "frame " << f << ", cube " << c;
      EXPECT_EQ(b.cubes[c].reason, a.cubes[c].reason) << "frame " << f << ", cube " << c;
      // The squared errors are summed in the records' order, the device's not the CPU's.
      EXPECT_NEAR(b.cubes[c].estimated_psnr_db, a.cubes[c].estimated_psnr_db,
                  1e-9 * std::abs(a.cubes[c].estimated_psnr_db))
          << "frame " << f << ", cube " << c;
      if (p.policy == CachePolicy::Auto)
        std::cout << "  cube " << c << ": " << a.cubes[c].mode << " (" << a.cubes[c].reason
                  << "), " << a.cubes[c].estimated_psnr_db << " dB\n";
    }
    hits += b.hits;
    if (device_frame) verified += b.verified;
    // The stores hold the same texels, bit for bit, and counted the frame's lookups and leaving
    // rays alike (what auto's savings are computed from).
    EXPECT_EQ(cpu_store.cube_count(), device_store.cube_count());
    for (std::size_t c = 0; c < std::min(cpu_store.cube_count(), device_store.cube_count()); ++c) {
      const cache::CubeFrameCounts ca = cpu_store.frame_counts(c),
                                   cb = device_store.frame_counts(c);
      EXPECT_TRUE(ca == cb) << "frame " << f << ", cube " << c << ": lookups " << cb.lookups << " ("
                            << ca.lookups << "), outdated " << cb.outdated << " (" << ca.outdated
                            << "), march steps " << cb.march_steps << " (" << ca.march_steps
                            << "), offered rays " << cb.offered_rays << " (" << ca.offered_rays
                            << "), used rays " << cb.used_rays << " (" << ca.used_rays
                            << "), traced rays " << cb.traced_rays << " (" << ca.traced_rays << ")";
      const auto ta = cpu_store.cube(c).texels, tb = device_store.cube(c).texels;
      EXPECT_TRUE(ta.size() == tb.size() &&
                  std::memcmp(ta.data(), tb.data(), ta.size_bytes()) == 0)
          << "cube " << c;
    }
  }
  EXPECT_GT(hits, 0u) << "no lookup was served: the test compares uncached frames only";
  if (p.policy == CachePolicy::Auto) {
    EXPECT_GT(verified, 0u) << "no device frame verified a lookup: its error went untested";
  } else {
    EXPECT_EQ(on_device, frames);
  }
  return on_device;
}

TEST_P(DeviceCacheFrames, StaticFramesEqualTheCpuFrames) {
  SPECULA_NEED_DEVICE();
  compare_frames(GetParam(), 3, -1);
}

TEST_P(DeviceCacheFrames, AfterAMoveAndInvalidationTheFrameEqualsTheCpuFrame) {
  SPECULA_NEED_DEVICE();
  compare_frames(GetParam(), 4, 2);
}

// Traces stopped by a budget of 16 steps go on from their saved walks (in Tau mode the confirming
// occlusion rays are budgeted traces too): the frames still equal the CPU's.
TEST_P(DeviceCacheFrames, SmallBudgetFramesEqualTheCpuFrames) {
  SPECULA_NEED_DEVICE();
  compare_frames(GetParam(), 2, -1, 16);
}

// --cache auto on device frames: verified lookups are chosen by the same hash, traced, and their
// errors reach the store with the texel and throughput the CPU would give it, so over a pan the
// policy takes the same decisions on both, and the images stay equal, every frame on the device
// (cubes on trial in march mode included). Once with every leaving ray recorded and its lookup
// (and verified texel) checked against the store's.
TEST(DeviceCacheAuto, APanDecidesAndRendersAsOnTheCpu) {
  SPECULA_NEED_DEVICE();
  using Records = gpu::DeviceCache::Records;
  for (const auto& [e, records] : {std::pair{gpu::Execution::wavefront, Records::changes},
                                   std::pair{gpu::Execution::single_kernel, Records::changes},
                                   std::pair{gpu::Execution::wavefront, Records::every}}) {
    const int frames = 14;
    const int on_device = compare_frames(
        Param{LookupMode::Direction, e, CachePolicy::Auto, records}, frames, 9, 0, 2.0f);
    std::cout << on_device << " of " << frames << " frames on the device\n";
    EXPECT_EQ(on_device, frames);
  }
}

/// A still view of CacheScene rendered on the device with a store of `mode` (wavefront or single
/// kernel, on a context made with `options`): frame() renders one more frame, cached or not.
struct StillView {
  CacheScene scene;
  test::TracedWorld world{scene.reg, "native-bvh", test::device_mirror_options()};
  RayCacheStore store;
  std::unique_ptr<gpu::Context> context;
  gpu::GpuScene gpu_scene;
  gpu::DeviceRenderer renderer;
  TraceSettings settings;
  Framebuffer image{kSize, kSize};
  FrameStats stats;
  gpu::GpuTraceCounters counters;

  StillView(LookupMode mode, gpu::Execution execution, const gpu::Context::Options& options = {})
      : store(settings_of(mode)), context(gpu::Context::create(options)),
        gpu_scene(*context, gpu::GpuStructure::bvh),
        renderer(*context, updated(gpu_scene, world.layer), execution) {
    settings.mode = TraceMode::Whitted;
    settings.max_depth = 4;
  }
  static gpu::GpuScene& updated(gpu::GpuScene& s, const SceneLayer& layer) {
    s.update(layer);
    return s;
  }
  static CacheSettings settings_of(LookupMode mode) {
    CacheSettings cs;
    cs.policy = CachePolicy::On;
    cs.lookup = mode;
    return cs;
  }
  void frame(bool cached = true) {
    if (!cached) {
      renderer.render(world.layer, scene.camera, settings, image, stats, counters);
      return;
    }
    (void)store.invalidate(scene.reg, world.layer);
    renderer.render(world.layer, scene.camera, settings, image, stats, counters, &store);
  }
};

// Once the cubes hold what a still view looks up, its frames hand the store no record at all:
// the kernels count the served rays (and the lookups) as the store would, so nothing in
// proportion to the pixels is read back or replayed on the host; recording every ray instead
// gives the same counts, texels and image (compare_frames checks both against the CPU).
TEST(DeviceCache, AFilledStillViewRecordsNothingAndCountsAsTheStore) {
  SPECULA_NEED_DEVICE();
  using Records = gpu::DeviceCache::Records;
  for (const LookupMode mode : {LookupMode::Direction, LookupMode::March}) {
    std::uint32_t last[2] = {0, 0};
    for (const Records records : {Records::changes, Records::every}) {
      StillView view(mode, gpu::Execution::wavefront);
      view.renderer.cache().set_records(records);
      std::uint32_t first = 0;
      for (int f = 0; f < 3; ++f) {
        view.frame();
        if (f == 0) first = view.renderer.cache_records();
        EXPECT_EQ(view.renderer.cache_mismatches(), 0u);
      }
      EXPECT_GT(first, 0u) << "the first frame wrote nothing: no test";
      EXPECT_GT(view.store.counts().hits, 0u);
      last[records == Records::every ? 1 : 0] = view.renderer.cache_records();
    }
    EXPECT_EQ(last[0], 0u) << cache::lookup_mode_name(mode);
    EXPECT_GT(last[1], 0u) << cache::lookup_mode_name(mode);
  }
}

// The cube table, the counts and the frame's parameters travel in the frame's own commands: once
// the cubes are filled, a cached frame of a still view waits for no more submits (host-device
// round trips) than the same frame uncached; the first frame, which writes texels, pays for its
// uploads and its records' read-back. Device memory unmapped, as on a discrete GPU (on lavapipe
// uploads and read-backs would otherwise be plain copies, with no submit to count).
TEST(DeviceCache, AFilledStillViewWaitsForNoMoreSubmitsThanAnUncachedFrame) {
  SPECULA_NEED_DEVICE();
  gpu::Context::Options unmapped;
  unmapped.map_device_memory = false;
  for (const gpu::Execution execution :
       {gpu::Execution::wavefront, gpu::Execution::single_kernel}) {
    SCOPED_TRACE(execution == gpu::Execution::wavefront ? "wavefront" : "single kernel");
    StillView view(LookupMode::Direction, execution, unmapped);
    ASSERT_FALSE(view.context->maps_device_memory());
    std::uint64_t first = 0;
    for (int f = 0; f < 3; ++f) {
      view.frame();
      if (f == 0) first = view.counters.submits;
    }
    const std::uint64_t cached = view.counters.submits;
    EXPECT_EQ(view.renderer.cache_records(), 0u) << "not a filled still view: no test";
    view.frame(false);
    const std::uint64_t uncached = view.counters.submits;
    EXPECT_GT(uncached, 0u);
    EXPECT_EQ(cached, uncached);
    EXPECT_GT(first, cached) << "the filling frame's records came back without a read-back";
  }
}

INSTANTIATE_TEST_SUITE_P(
    Modes, DeviceCacheFrames,
    ::testing::Values(Param{LookupMode::Direction, gpu::Execution::wavefront},
                      Param{LookupMode::Tau, gpu::Execution::wavefront},
                      Param{LookupMode::March, gpu::Execution::wavefront},
                      Param{LookupMode::Direction, gpu::Execution::single_kernel},
                      Param{LookupMode::Tau, gpu::Execution::single_kernel},
                      Param{LookupMode::March, gpu::Execution::single_kernel},
                      Param{LookupMode::Direction, gpu::Execution::wavefront, CachePolicy::On,
                            gpu::DeviceCache::Records::every},
                      Param{LookupMode::Tau, gpu::Execution::single_kernel, CachePolicy::On,
                            gpu::DeviceCache::Records::every},
                      Param{LookupMode::March, gpu::Execution::wavefront, CachePolicy::On,
                            gpu::DeviceCache::Records::every},
                      Param{LookupMode::Tau, gpu::Execution::wavefront, CachePolicy::On,
                            gpu::DeviceCache::Records::changes, 500},
                      Param{LookupMode::Direction, gpu::Execution::wavefront, CachePolicy::On,
                            gpu::DeviceCache::Records::every, 500}),
    [](const auto& param_info) {
      return std::string(cache::lookup_mode_name(param_info.param.mode)) +
             (param_info.param.execution == gpu::Execution::wavefront ? "_wavefront" : "_single") +
             (param_info.param.records == gpu::DeviceCache::Records::every ? "_every_record" : "") +
             (param_info.param.chunk > 0 ? "_chunks" : "");
    });

TEST(DeviceCache, ARenderJobWithCachesRendersOnTheDeviceAsOnTheCpu) {
  // `--backend vulkan --cache on` through prepare_rendering and the schedule (invalidation
  // system, render system): the job's hook is the store, and the device frames take it.
  SPECULA_NEED_DEVICE();
  std::vector<Framebuffer> images[2];
  std::uint64_t hits[2] = {0, 0}, cut = 0, records = 0;
  for (int k = 0; k < 2; ++k) {
    CacheScene scene;
    test::add_camera(scene.reg, vec3(scene.camera.position), vec3(scene.camera.look_at), 45.0f);
    RenderJob job;
    job.backend = k == 0 ? "native-bvh" : "vulkan";
    job.native_wide_bvh = false; // the device's mirror (test::device_mirror_options)
    job.settings.mode = TraceMode::Whitted;
    job.settings.max_depth = 4;
    job.settings.threads = 2;
    job.image = Framebuffer(kSize, kSize);
    job.cache.policy = CachePolicy::On;
    job.cache.lookup = LookupMode::Tau;
    prepare_rendering(scene.reg, std::move(job));
    Schedule schedule;
    for (int f = 0; f < 3; ++f) {
      if (f == 2)
        scene.reg.patch<Transform>(scene.mover, [](Transform& t) { t.translation.x += 0.8f; });
      schedule.tick(scene.reg, 1.0 / 60.0);
      const RenderJob& done = scene.reg.resource<RenderJob>();
      images[k].push_back(done.image);
      hits[k] += scene.reg.resource<cache::RayCaches>().store->counts().hits;
      if (const auto* vulkan = dynamic_cast<const gpu::VulkanTracer*>(
              scene.reg.resource<ActiveTracer>().tracer.get())) {
        cut += vulkan->counters().cut;
        records += vulkan->renderer().cache_records(); // 0 unless a device frame took the store
      }
    }
  }
  for (std::size_t f = 0; f < images[0].size(); ++f) {
    EXPECT_EQ(test::differing_pixels(images[0][f], images[1][f]), 0u) << "frame " << f;
  }
  EXPECT_EQ(hits[1], hits[0]);
  EXPECT_GT(hits[1], 0u);
  EXPECT_GT(records, 0u) << "the vulkan frames did not run on the device";
  EXPECT_EQ(cut, 0u);
}

TEST(DeviceCache, OnlyStoresTheDeviceServesAreAccepted) {
  SPECULA_NEED_DEVICE();
  CacheScene scene;
  test::TracedWorld world(scene.reg, "native-bvh", test::device_mirror_options());
  auto context = gpu::Context::create();
  gpu::GpuScene gpu_scene(*context, gpu::GpuStructure::bvh);
  gpu_scene.update(world.layer);
  gpu::DeviceRenderer renderer(*context, gpu_scene, gpu::Execution::wavefront);
  TraceSettings s;
  s.mode = TraceMode::Whitted;
  CacheSettings on;
  on.policy = CachePolicy::On;
  CacheSettings march = on, automatic = on;
  march.lookup = LookupMode::March;
  automatic.policy = CachePolicy::Auto;
  RayCacheStore a(on), b(march), c(automatic);
  EXPECT_TRUE(renderer.supports(s, nullptr, false));
  EXPECT_TRUE(renderer.supports(s, &a, false));
  EXPECT_TRUE(renderer.supports(s, &b, false)); // march mode runs in the kernels too
  EXPECT_TRUE(renderer.supports(s, &c, false)); // auto, its cubes starting in direction mode
  struct Other final : RadianceHook {
    void leaving(std::span<const LeavingRadiance>) override {}
  } other;
  EXPECT_FALSE(renderer.supports(s, &other, false));
  Framebuffer out(8, 8);
  FrameStats stats;
  gpu::GpuTraceCounters counters;
  EXPECT_THROW(renderer.render(world.layer, scene.camera, s, out, stats, counters, &other), Error);
}

} // namespace
} // namespace specula
