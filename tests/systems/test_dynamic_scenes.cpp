// Frame-to-frame coherence of animated scenes (issue 11), through the whole schedule on the native
// and Embree backends: static parts are built once, hierarchical parts cost only the top level,
// free parts are refitted (and restructured once they degrade: subtrees on the native BVH, the
// whole mesh on Embree), and every frame still matches a from-scratch build of the same scene time.

#include "../trace/scene_builder.h"
#include "specula/render/tracer_factory.h"
#include "specula/scene/scene.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace specula {
namespace {

// Scene times are multiples of 3/8 s: exact in float, so ticking there in steps and jumping there
// in one tick give the same animation clocks (bit for bit), and the images can be compared exactly.
constexpr double kStep = 0.375;
constexpr int kFrames = 10;
constexpr std::uint32_t kWidth = 48, kHeight = 40;

Scene sample_scene() {
  return load_scene(std::filesystem::path(SPECULA_SOURCE_DIR) /
                    "samples/scenes/dynamic_three_classes.json");
}

bool available(const std::string& backend) { return backend_info(backend).available; }

void prepare(ecs::Registry& registry, const std::string& backend, std::uint32_t width = kWidth,
             std::uint32_t height = kHeight) {
  RenderJob job;
  job.backend = backend;
  job.settings.mode = TraceMode::Whitted;
  job.settings.max_depth = 2;
  job.settings.threads = 2;
  job.image = Framebuffer(width, height);
  prepare_rendering(registry, std::move(job));
}

/// Triangles of the mesh entities of one kinematic class (each entity's mesh counted once).
std::uint64_t triangles_of(ecs::Registry& registry, Kinematics::Type type) {
  std::uint64_t n = 0;
  registry.view<Mesh, Kinematics>().each([&](ecs::Entity, const Mesh& m, const Kinematics& k) {
    if (k.type == type) n += m.geometry->triangles.size();
  });
  return n;
}

/// The image of the sample at scene time `time`, everything built from scratch in one tick.
std::vector<vec3> from_scratch(const std::string& backend, double time) {
  Scene scene = sample_scene();
  prepare(scene.registry, backend);
  Schedule schedule;
  schedule.tick(scene.registry, time);
  const auto px = scene.registry.resource<RenderJob>().image.pixels();
  return {px.begin(), px.end()};
}

class DynamicScenes : public ::testing::TestWithParam<std::string> {};

TEST_P(DynamicScenes, StaticPartsAreBuiltOnceHierarchicalOnlyTopLevelFreeRefitted) {
  const std::string backend = GetParam();
  if (!available(backend)) GTEST_SKIP() << backend << " is not in this build";
  Scene scene = sample_scene();
  const std::uint64_t free_triangles = triangles_of(scene.registry, Kinematics::Type::Free);
  const std::uint64_t fixed_triangles =
      triangles_of(scene.registry, Kinematics::Type::Static) +
      triangles_of(scene.registry, Kinematics::Type::Hierarchical);
  ASSERT_GT(free_triangles, 0u);
  ASSERT_GT(fixed_triangles, 0u);
  prepare(scene.registry, backend);
  Schedule schedule;
  std::uint32_t restructures = 0;
  for (int k = 0; k < kFrames; ++k) {
    schedule.tick(scene.registry, k == 0 ? 0.0 : kStep);
    const FrameStats& f = scene.registry.resource<RenderJob>().last;
    const AccelStats& a = f.accel;
    EXPECT_DOUBLE_EQ(f.time, k * kStep);
    if (k == 0) {
      EXPECT_EQ(a.static_builds, 1u);
      EXPECT_GT(a.blas_builds, 0u);
      EXPECT_GT(a.triangles_rebuilt, 0u);
      continue;
    }
    SCOPED_TRACE("frame " + std::to_string(k));
    EXPECT_EQ(a.static_builds, 0u) << "the static room is never rebuilt after frame 0";
    EXPECT_EQ(a.blas_builds, 0u) << "the moving car costs only the top level";
    EXPECT_GT(a.top_build_ms, 0.0) << "the car moved: the top level was rebuilt";
    EXPECT_EQ(a.refits, 2u) << "the flag and the swarm deform every frame";
    // Only the free meshes' triangles are touched; the room's and the car's never are.
    EXPECT_EQ(a.triangles_rebuilt + a.triangles_refit, free_triangles);
    EXPECT_GE(a.triangles_untouched, fixed_triangles);
    restructures += a.restructures;
  }
  // The swarm scatters through the room: its boxes degrade past the threshold (on Embree, those
  // of the stand-in tree that watches its BLAS).
  EXPECT_GT(restructures, 0u) << "the scattering swarm must trigger selective restructuring";
}

TEST_P(DynamicScenes, EveryFrameMatchesAFromScratchBuildOfItsTime) {
  const std::string backend = GetParam();
  if (!available(backend)) GTEST_SKIP() << backend << " is not in this build";
  Scene scene = sample_scene();
  prepare(scene.registry, backend);
  Schedule schedule;
  for (int k = 0; k < kFrames; ++k) {
    schedule.tick(scene.registry, k == 0 ? 0.0 : kStep);
    if (k % 3 != 0) continue; // a few frames keep the test fast; the updates run on every one
    const auto px = scene.registry.resource<RenderJob>().image.pixels();
    const std::vector<vec3> incremental(px.begin(), px.end());
    const std::vector<vec3> fresh = from_scratch(backend, k * kStep);
    ASSERT_EQ(incremental.size(), fresh.size());
    std::size_t differ = 0;
    for (std::size_t i = 0; i < fresh.size(); ++i) differ += incremental[i] != fresh[i] ? 1 : 0;
    EXPECT_EQ(differ, 0u) << "frame " << k << " (time " << k * kStep << ") on " << backend;
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, DynamicScenes, ::testing::Values("native", "embree"),
                         [](const auto& p) { return p.param; });

/// A free mesh (a tessellated sphere) keyed from its rest shape to `moved` and back.
Scene free_mesh_scene(const std::function<vec3(const vec3&, std::size_t)>& moved) {
  Scene scene;
  ecs::Registry& reg = scene.registry;
  test::add_mesh(reg, test::primitive("plane", 1, vec3(20, 1, 20)), test::at(vec3(0)));
  const ecs::Entity blob =
      test::add_mesh(reg, test::primitive("sphere", 1.0f, vec3(1), 32, 16), test::at(vec3(0, 1, 0)),
                     Material{}, Kinematics::Type::Free);
  const std::vector<vec3>& rest = reg.get<Mesh>(blob).geometry->positions;
  std::vector<vec3> target(rest.size());
  for (std::size_t i = 0; i < rest.size(); ++i) target[i] = moved(rest[i], i);
  Animation anim;
  anim.vertices.times = {0.0f, 1.0f, 2.0f};
  anim.vertices.values = {rest, target, rest};
  reg.emplace<Animation>(blob, anim);
  test::add_camera(reg, vec3(0, 2, 6), vec3(0, 1, 0));
  test::add_point_light(reg, vec3(0, 6, 3), 40.0f);
  return scene;
}

/// Restructures over ten frames of 1/8 s on `backend`.
std::uint32_t restructures_on(const std::string& backend, Scene scene) {
  prepare(scene.registry, backend, 8, 8);
  Schedule schedule;
  std::uint32_t restructures = 0, refits = 0;
  for (int k = 0; k < kFrames; ++k) {
    schedule.tick(scene.registry, k == 0 ? 0.0 : 0.125);
    restructures += scene.registry.resource<RenderJob>().last.accel.restructures;
    refits += scene.registry.resource<RenderJob>().last.accel.refits;
  }
  EXPECT_EQ(refits, std::uint32_t(kFrames - 1)) << "refitted on every frame after the first";
  return restructures;
}

class Restructuring : public ::testing::TestWithParam<std::string> {};

TEST_P(Restructuring, HappensWhenDeformationDegradesTheTreeNotWhenItMovesRigidly) {
  const std::string backend = GetParam();
  if (!available(backend)) GTEST_SKIP() << backend << " is not in this build";
  // Rigid: every vertex shifted alike; the refitted tree is the built one, translated.
  const auto rigid = [](const vec3& p, std::size_t) { return p + vec3(2.5f, 0.5f, -1.0f); };
  EXPECT_EQ(restructures_on(backend, free_mesh_scene(rigid)), 0u);
  // Degrading: the vertices of neighbouring triangles fly apart (a seeded-free scatter: each
  // vertex leaves along a direction given by its index), so the refitted boxes swell and overlap.
  const auto scatter = [](const vec3& p, std::size_t i) {
    const float a = float(i) * 2.399963f; // the golden angle: spread, deterministic
    return p + 3.0f * vec3(std::cos(a), 0.3f * std::sin(1.7f * a), std::sin(a));
  };
  EXPECT_GT(restructures_on(backend, free_mesh_scene(scatter)), 0u);
}

INSTANTIATE_TEST_SUITE_P(Backends, Restructuring, ::testing::Values("native", "embree"),
                         [](const auto& p) { return p.param; });

} // namespace
} // namespace specula
