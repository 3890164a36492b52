// The tracer factory: names, availability, and `auto`'s choice by the scene's kind.
#include "scene_builder.h"
#include "specula/core/error.h"
#include "specula/render/tracer_factory.h"

#if SPECULA_HAS_VULKAN
#include "specula/gpu/vulkan_tracer.h"
#endif

#include <gtest/gtest.h>

#include <cstdlib>
#include <optional>
#include <string>

namespace specula {
namespace {

TEST(TracerFactory, SceneKindFollowsKinematicsAndVertexAnimation) {
  ecs::Registry reg;
  test::add_mesh(reg, test::primitive("box"), test::at(vec3(0)));
  EXPECT_EQ(scene_kind(reg), SceneKind::static_only);
  test::add_mesh(reg, test::primitive("sphere"), test::at(vec3(3, 0, 0)), Material{},
                 Kinematics::Type::Free);
  EXPECT_EQ(scene_kind(reg), SceneKind::rigid_dynamic);
  const ecs::Entity blob = test::add_mesh(reg, test::primitive("sphere"), test::at(vec3(-3, 0, 0)),
                                          Material{}, Kinematics::Type::Free);
  Animation anim;
  const auto& rest = reg.get<Mesh>(blob).geometry->positions;
  anim.vertices.times = {0.0f, 1.0f};
  anim.vertices.values = {rest, rest};
  reg.emplace<Animation>(blob, anim);
  EXPECT_EQ(scene_kind(reg), SceneKind::deforming);
}

TEST(TracerFactory, AutoTakesTheFirstAvailableCpuBackendInTheKindsOrder) {
  for (const SceneKind kind : {SceneKind::static_only, SceneKind::rigid_dynamic,
                               SceneKind::deforming}) {
    std::string expected;
    for (const std::string_view name : cpu_preference(kind))
      if (expected.empty() && backend_info(name).available) expected = std::string(name);
    if (backend_info("vulkan").available && !auto_cpu_reason(kind)) expected = "vulkan";
    EXPECT_EQ(resolve_backend("auto", kind), expected) << scene_kind_name(kind);
    EXPECT_EQ(make_tracer("auto", 1, kind)->name(), expected);
  }
}

// The CLI checks --backend against backend_names(), which does not create a Vulkan instance to
// find out what is available; it must list what backends() lists, in the same order.
TEST(TracerFactory, BackendNamesAreThoseOfBackends) {
  const std::vector<BackendInfo> all = backends();
  const std::span<const std::string_view> names = backend_names();
  ASSERT_EQ(all.size(), names.size());
  for (std::size_t i = 0; i < all.size(); ++i) EXPECT_EQ(all[i].name, names[i]) << i;
  for (const std::string_view name : names) EXPECT_TRUE(is_backend_name(name)) << name;
  EXPECT_TRUE(is_backend_name("auto"));
  EXPECT_FALSE(is_backend_name("optix"));
  EXPECT_FALSE(is_backend_name(""));
}

TEST(TracerFactory, EveryAvailableBackendMakesATracerOfThatName) {
  for (const BackendInfo& b : backends()) {
    if (!b.available) {
      EXPECT_THROW((void)make_tracer(b.name), UnavailableError) << b.name;
      continue;
    }
    EXPECT_EQ(make_tracer(b.name)->name(), b.name);
  }
  EXPECT_TRUE(backend_info("native").available) << "the native backend is in every build";
  EXPECT_TRUE(backend_info("native").watertight);
  EXPECT_THROW((void)backend_info("optix"), Error);
  EXPECT_THROW((void)resolve_backend("optix"), Error);
}

/// Sets an environment variable for a scope (the factory's probe follows SPECULA_VK_DEVICE).
class ScopedEnv {
public:
  ScopedEnv(const char* name, const char* value) : name_(name) {
    if (const char* old = std::getenv(name)) old_ = old;
    ::setenv(name, value, 1);
  }
  ~ScopedEnv() {
    if (old_)
      ::setenv(name_, old_->c_str(), 1);
    else
      ::unsetenv(name_);
  }
  ScopedEnv(const ScopedEnv&) = delete;
  ScopedEnv& operator=(const ScopedEnv&) = delete;

private:
  const char* name_;
  std::optional<std::string> old_;
};

TEST(TracerFactory, AutoNeverPicksASoftwareVulkanDevice) {
  bool real_gpu = false;
  for (const VulkanDeviceEntry& d : vulkan_devices())
    if (d.compute && d.type != "CPU (software)") real_gpu = true;
  EXPECT_EQ(resolve_backend("auto") == "vulkan", real_gpu);
  EXPECT_EQ(auto_cpu_reason().has_value(), !real_gpu);
  if (!real_gpu) {
    EXPECT_NE(make_tracer("auto")->name().substr(0, 6), "vulkan");
    EXPECT_NE(auto_cpu_reason()->find("no Vulkan GPU"), std::string::npos) << *auto_cpu_reason();
  }
}

TEST(TracerFactory, VulkanIsAvailableExactlyWhenADeviceIs) {
  std::string why;
  bool compute = false;
  for (const VulkanDeviceEntry& d : vulkan_devices(&why)) compute = compute || d.compute;
  EXPECT_EQ(backend_info("vulkan").available, compute) << why;
  EXPECT_EQ(backend_info("vulkan-grid").available, compute) << why;
  {
    // The probe sees what Context::create sees: SPECULA_VK_DEVICE naming no device leaves none.
    const ScopedEnv none("SPECULA_VK_DEVICE", "no-such-device");
    for (const char* name : {"vulkan", "vulkan-grid"}) {
      const BackendInfo b = backend_info(name);
      EXPECT_FALSE(b.available) << name;
#if SPECULA_HAS_VULKAN
      EXPECT_NE(b.reason.find("no-such-device"), std::string::npos) << b.reason;
#else
      // A build without the backend says so, whatever the device variable names.
      EXPECT_NE(b.reason.find("SPECULA_WITH_VULKAN=OFF"), std::string::npos) << b.reason;
#endif
      EXPECT_THROW((void)make_tracer(name), UnavailableError) << name;
    }
    EXPECT_NE(resolve_backend("auto"), "vulkan");
    ASSERT_TRUE(auto_cpu_reason().has_value());
    for (const VulkanDeviceEntry& d : vulkan_devices()) EXPECT_FALSE(d.chosen) << d.name;
  }
  EXPECT_EQ(backend_info("vulkan").available, compute) << "the probe follows the variable back";
}

#if SPECULA_HAS_VULKAN
TEST(TracerFactory, GpuOptionsReachTheVulkanTracer) {
  if (!backend_info("vulkan-grid").available) GTEST_SKIP() << "no Vulkan device here";
  TracerOptions options;
  options.packet_width = 8;
  options.gpu.execution = GpuTracerOptions::Execution::single_kernel;
  options.gpu.device_frames = false;
  options.gpu.grid_density = 0.5f;
  const std::unique_ptr<Tracer> tracer = make_tracer("vulkan-grid", options);
  const auto* vk = dynamic_cast<const gpu::VulkanTracer*>(tracer.get());
  ASSERT_NE(vk, nullptr);
  EXPECT_EQ(vk->options().structure, gpu::GpuStructure::grid);
  EXPECT_EQ(vk->options().execution, gpu::Execution::single_kernel);
  EXPECT_FALSE(vk->options().device_frames);
  EXPECT_EQ(vk->options().grid_density, 0.5f);
  EXPECT_EQ(tracer->packet_width(), 8u);
  const std::optional<TracerDevice> device = tracer_device(*tracer);
  ASSERT_TRUE(device.has_value());
  EXPECT_EQ(device->name, vk->context().info().name);
  EXPECT_EQ(device->execution, "single kernel");
  EXPECT_FALSE(tracer_device(*make_tracer("native")).has_value()) << "CPU tracers have no device";
  options.gpu.grid_density = 0.0f;
  EXPECT_THROW((void)make_tracer("vulkan-grid", options), Error);
}

TEST(TracerFactory, RasterisedPrimaryVisibilityReachesTheVulkanTracer) {
  if (!backend_info("vulkan").available) GTEST_SKIP() << "no Vulkan device here";
  if (!dynamic_cast<gpu::VulkanTracer&>(*make_tracer("vulkan")).context().info().graphics)
    GTEST_SKIP() << "the device cannot draw";
  TracerOptions options;
  options.gpu.primary = GpuTracerOptions::Primary::raster;
  const std::unique_ptr<Tracer> tracer = make_tracer("vulkan", options);
  const auto* vk = dynamic_cast<const gpu::VulkanTracer*>(tracer.get());
  ASSERT_NE(vk, nullptr);
  EXPECT_EQ(vk->options().primary, gpu::PrimaryVisibility::raster);
  EXPECT_EQ(tracer_device(*tracer)->primary, "raster");
}

TEST(TracerFactory, TheTestOnlyDeviceLossKnobLosesTheNewTracersDevice) {
  if (!backend_info("vulkan").available) GTEST_SKIP() << "no Vulkan device here";
  EXPECT_FALSE(dynamic_cast<gpu::VulkanTracer&>(*make_tracer("vulkan")).context().lost());
  const ScopedEnv lose("SPECULA_VK_SIMULATE_DEVICE_LOSS", "1");
  const std::unique_ptr<Tracer> tracer = make_tracer("vulkan");
  gpu::Context& context = dynamic_cast<gpu::VulkanTracer&>(*tracer).context();
  EXPECT_TRUE(context.lost());
  // What the CLI turns into exit 3: the next submit reports the lost device.
  try {
    context.run_now([](VkCommandBuffer) {});
    ADD_FAILURE() << "a submit on a lost device must fail";
  } catch (const gpu::GpuError& e) {
    EXPECT_TRUE(e.device_lost()) << e.what();
    EXPECT_TRUE(is_device_failure(e)) << "the CLI reports it as the backend's failure";
  }
  EXPECT_FALSE(is_device_failure(Error("scene.json", "bad input")));
  EXPECT_FALSE(is_device_failure(UnavailableError("no such mode")));
}
#endif

} // namespace
} // namespace specula
