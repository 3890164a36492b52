// The Vulkan foundation (engine/gpu/vk_context.h): device choice, buffers, a compute dispatch with
// push and specialization constants, timestamps, the simulated device loss, and the driver's
// silent loop cap that every kernel's loops must stay under.
#include "specula/core/error.h"
#include "specula/gpu/shaders.h"
#include "specula/gpu/vk_context.h"

#include <gtest/gtest.h>

#include <cstdlib>
#include <iostream>
#include <numeric>
#include <vector>

namespace specula::gpu {
namespace {

std::unique_ptr<Context> try_context() {
  try {
    return Context::create();
  } catch (const UnavailableError&) {
    return nullptr;
  }
}

#define SPECULA_NEED_DEVICE(ctx)                                                                   \
  auto ctx = try_context();                                                                        \
  if (!ctx) GTEST_SKIP() << "no Vulkan device on this machine"

struct SelftestPush {
  std::uint32_t offset, count, loop_count;
};

TEST(VkContext, ListsTheDeviceItOpens) {
  SPECULA_NEED_DEVICE(ctx);
  const auto devices = list_devices();
  ASSERT_FALSE(devices.empty());
  bool listed = false;
  for (const auto& d : devices) listed |= d.name == ctx->info().name;
  EXPECT_TRUE(listed) << ctx->info().name;
  EXPECT_GT(ctx->info().max_storage_buffer_range, 0u);
}

TEST(VkContext, DeviceNameThatMatchesNothingIsAClearUnavailableError) {
  SPECULA_NEED_DEVICE(ctx);
  Context::Options options;
  options.device_name = "no-such-device-xyz";
  try {
    (void)Context::create(options);
    FAIL() << "expected UnavailableError";
  } catch (const UnavailableError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("no-such-device-xyz"), std::string::npos) << what;
    EXPECT_NE(what.find(ctx->info().name), std::string::npos) << what; // lists the devices
  }
}

TEST(VkContext, BuffersRoundTripInBothMemoryKinds) {
  SPECULA_NEED_DEVICE(ctx);
  std::vector<std::uint32_t> data(1000);
  std::iota(data.begin(), data.end(), 7u);
  for (MemoryKind kind : {MemoryKind::device, MemoryKind::host}) {
    Buffer b = ctx->make_buffer(data.size() * 4, kind);
    b.upload(std::span<const std::uint32_t>(data));
    std::vector<std::uint32_t> back(data.size());
    b.download(std::span<std::uint32_t>(back));
    EXPECT_EQ(back, data);
  }
}

// A context that never maps device memory takes a discrete GPU's paths on any device: uploads,
// scattered uploads and read-backs through the staging buffer, each a submit of its own; host
// buffers stay mapped.
TEST(VkContext, UnmappedDeviceMemoryGoesThroughStagingCopies) {
  SPECULA_NEED_DEVICE(any);
  Context::Options options;
  options.map_device_memory = false;
  const std::unique_ptr<Context> ctx = Context::create(options);
  ASSERT_FALSE(ctx->maps_device_memory());
  std::vector<std::uint32_t> data(1000);
  std::iota(data.begin(), data.end(), 7u);
  Buffer b = ctx->make_buffer(data.size() * 4);
  EXPECT_EQ(b.mapped(), nullptr);
  EXPECT_NE(ctx->make_buffer(64, MemoryKind::host).mapped(), nullptr);
  const std::uint64_t before = ctx->submits();
  b.upload(std::span<const std::uint32_t>(data));
  EXPECT_EQ(ctx->submits(), before + 1);
  // Two runs of new values, from one staging copy.
  const std::vector<std::uint32_t> runs = {1, 2, 3, 4, 5};
  const VkBufferCopy pieces[] = {{0, 10 * 4, 2 * 4}, {2 * 4, 500 * 4, 3 * 4}};
  b.scatter(runs.data(), runs.size() * 4, pieces);
  EXPECT_EQ(ctx->submits(), before + 2);
  std::copy(runs.begin(), runs.begin() + 2, data.begin() + 10);
  std::copy(runs.begin() + 2, runs.end(), data.begin() + 500);
  std::vector<std::uint32_t> back(data.size());
  b.download(std::span<std::uint32_t>(back));
  EXPECT_EQ(ctx->submits(), before + 3);
  EXPECT_EQ(back, data);
}

TEST(VkContext, DispatchAppliesPushAndSpecializationConstants) {
  SPECULA_NEED_DEVICE(ctx);
  const std::uint32_t n = 1000;
  Pipeline pipeline = ctx->make_pipeline(
      {shader_spirv("selftest"), 3, sizeof(SelftestPush), {3u}, "selftest"});
  std::vector<std::uint32_t> in(n);
  std::iota(in.begin(), in.end(), 0u);
  Buffer bin = ctx->make_buffer(n * 4), bout = ctx->make_buffer(n * 4), loops = ctx->make_buffer(n * 4);
  bin.upload(std::span<const std::uint32_t>(in));
  Commands cmd(*ctx);
  const SelftestPush push{5u, n, 4u};
  const std::uint32_t t0 = cmd.timestamp();
  cmd.dispatch(pipeline, {&bin, &bout, &loops}, &push, (n + 63) / 64);
  const std::uint32_t t1 = cmd.timestamp();
  cmd.submit();
  std::vector<std::uint32_t> out(n), done(n);
  bout.download(std::span<std::uint32_t>(out));
  loops.download(std::span<std::uint32_t>(done));
  for (std::uint32_t i = 0; i < n; ++i) {
    ASSERT_EQ(out[i], 3u * i + 5u) << i;
    ASSERT_EQ(done[i], 4u) << i;
  }
  if (ctx->info().timestamps) {
    EXPECT_GE(cmd.elapsed_ms(t0, t1), 0.0);
  }
}

TEST(VkContext, SimulatedDeviceLossThrowsDeviceLostOnEverySubmit) {
  SPECULA_NEED_DEVICE(ctx);
  ctx->simulate_device_loss();
  Commands cmd(*ctx);
  cmd.barrier();
  for (int attempt = 0; attempt < 2; ++attempt) {
    try {
      cmd.submit();
      FAIL() << "expected GpuError";
    } catch (const GpuError& e) {
      EXPECT_TRUE(e.device_lost()) << e.what();
    }
  }
  Buffer b = ctx->make_buffer(64); // creating objects still works; using the queue does not
  std::vector<std::uint32_t> x(16, 1u);
  if (b.mapped() == nullptr) {
    EXPECT_THROW(b.upload(std::span<const std::uint32_t>(x)), GpuError);
  }
}

// PLATFORM-NOTES: lavapipe ends any loop past 65,535 iterations per dispatch without an error.
// This documents the cap on the machine the tests run on, and so why every kernel bounds its
// loops: a loop within the budget completes, one far beyond it may not.
TEST(VkContext, LoopsWithinTheBudgetComplete) {
  SPECULA_NEED_DEVICE(ctx);
  const std::uint32_t n = 64;
  Pipeline pipeline = ctx->make_pipeline({shader_spirv("selftest"), 3, sizeof(SelftestPush), {1u}});
  Buffer bin = ctx->make_buffer(n * 4), bout = ctx->make_buffer(n * 4), loops = ctx->make_buffer(n * 4);
  for (const std::uint32_t iterations : {1000u, 8000u, 60000u, 200000u}) {
    Commands cmd(*ctx);
    const SelftestPush push{0u, n, iterations};
    cmd.dispatch(pipeline, {&bin, &bout, &loops}, &push, 1);
    cmd.submit();
    std::vector<std::uint32_t> done(n);
    loops.download(std::span<std::uint32_t>(done));
    if (iterations <= 60000u) {
      for (std::uint32_t i = 0; i < n; ++i) ASSERT_EQ(done[i], iterations) << i;
    } else if (ctx->info().is_cpu()) {
      std::uint32_t cut = 0;
      for (std::uint32_t i = 0; i < n; ++i) cut += done[i] < iterations ? 1u : 0u;
      RecordProperty("lanes_cut_at_200000_iterations", int(cut));
      std::cout << "lavapipe cut " << cut << " of " << n << " lanes at " << iterations
                << " iterations\n";
    }
  }
}

} // namespace
} // namespace specula::gpu
