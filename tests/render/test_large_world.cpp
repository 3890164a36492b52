// Large worlds (docs/design/large-worlds.md): a sample scene moved far from the world origin —
// every position offset in double, camera and lights included — renders like the same scene at
// the origin, on every backend of the build:
//   - static geometry (baked into camera-relative render space) at 1e7;
//   - every mesh an instance (hierarchical: per-mesh structures, transforms per frame) at 1e9;
// within 40 dB PSNR of the origin render and without acne: no pixel that is lit at the origin
// turns black, and no pixel stands out from all its neighbours where the origin render is smooth.
// Before camera-relative rendering, at 1e7 the sphere turned into a block, the ground showed
// salt-and-pepper acne and a shadow vanished.
// A rebase (the render origin moving to the camera) leaves no trace in the image.
// Also the representable range (issue 13, cause 1): scenes just inside ±1e12 render finite
// pixels on every backend; composition that leaves it at run time is an error naming the entity.

#include "scene_builder.h"
#include "specula/core/error.h"
#include "specula/image/metrics.h"
#include "specula/render/render_job.h"
#include "specula/scene/scene.h"
#include "specula/systems/schedule.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <tuple>

namespace specula {
namespace {

constexpr std::uint32_t kSize = 160;
constexpr double kMinPsnr = 40.0;

Scene load_sample(const std::string& name) {
  return load_scene(std::filesystem::path(SPECULA_SOURCE_DIR) / "samples/scenes" /
                    (name + ".json"));
}

/// Offsets every world position of the scene by `offset`, in double: the translations of root
/// entities (children follow their parents), their animation translation keys, cameras and
/// camera paths. Directions (rotations, directional lights) are unchanged.
void translate_world(ecs::Registry& reg, const dvec3& offset) {
  reg.view<Transform>().each([&](ecs::Entity e, Transform& t) {
    const Parent* parent = reg.try_get<Parent>(e);
    if (parent != nullptr && !parent->entity.is_null()) return;
    t.translation += offset;
    if (Animation* a = reg.try_get<Animation>(e))
      for (dvec3& key : a->translation.values) key += offset;
  });
  reg.view<Camera>().each([&](Camera& c) {
    c.position += offset;
    c.look_at += offset;
  });
  reg.view<CameraPath>().each([&](CameraPath& path) {
    for (CameraPath::Key& k : path.keys) {
      k.position += offset;
      k.look_at += offset;
    }
  });
  update_world_transforms(reg, 0);
}

void make_every_mesh_an_instance(ecs::Registry& reg) {
  reg.view<Mesh>().each([&](ecs::Entity e, const Mesh&) {
    reg.emplace_or_replace<Kinematics>(e, Kinematics{Kinematics::Type::Hierarchical});
  });
}

struct Frame {
  Framebuffer image;
  SceneLayerStats layer;
  dvec3 render_origin;
};

Frame render(Scene& scene, const std::string& backend, TraceMode mode) {
  Framebuffer image = test::render_scene(scene, mode, backend, kSize, kSize);
  const SceneLayer& layer = scene.registry.resource<SceneLayer>();
  return {std::move(image), layer.stats(), layer.render_origin()};
}

float luminance(const vec3& c) {
  const vec3 v = glm::clamp(c, vec3(0.0f), vec3(1.0f));
  return 0.2126f * v.x + 0.7152f * v.y + 0.0722f * v.z;
}

/// Acne in `moved` against the `origin` render of the same view: interior pixels where the
/// origin render is smooth (its 3×3 neighbourhood within 0.05 in luminance) and the moved one is
/// black although the origin pixel is lit, or differs by more than 0.1 from all 8 neighbours.
int acne_pixels(const Framebuffer& origin, const Framebuffer& moved) {
  int count = 0;
  for (std::uint32_t y = 1; y + 1 < origin.height(); ++y)
    for (std::uint32_t x = 1; x + 1 < origin.width(); ++x) {
      const float o = luminance(origin.at(x, y));
      bool smooth = true;
      bool stands_out = true;
      const float m = luminance(moved.at(x, y));
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          if (dx == 0 && dy == 0) continue;
          const std::uint32_t nx = x + dx, ny = y + dy;
          smooth = smooth && std::abs(luminance(origin.at(nx, ny)) - o) <= 0.05f;
          stands_out = stands_out && std::abs(luminance(moved.at(nx, ny)) - m) > 0.1f;
        }
      if (!smooth) continue;
      const bool blacked = o > 0.02f && m < 0.1f * o;
      if (blacked || stands_out) ++count;
    }
  return count;
}

class LargeWorld : public ::testing::TestWithParam<std::tuple<std::string, TraceMode>> {};

/// Static geometry at 1e7: baked relative to the render origin, which the first sync puts at the
/// camera.
TEST_P(LargeWorld, SceneAt1e7RendersLikeAtTheOrigin) {
  const auto& [backend, mode] = GetParam();
  Scene at_origin = load_sample("mirror_spheres_1");
  const Frame reference = render(at_origin, backend, mode);
  EXPECT_EQ(reference.render_origin, dvec3(0.0)) << "a camera near the origin keeps world space";

  Scene far = load_sample("mirror_spheres_1");
  const dvec3 offset(1e7, -3e6, 7e6);
  translate_world(far.registry, offset);
  const Frame moved = render(far, backend, mode);
  EXPECT_GT(glm::length(moved.render_origin), 1e6) << "the render origin follows the camera";
  EXPECT_GT(moved.layer.static_instances, 0u);

  const double db = psnr(reference.image, moved.image);
  EXPECT_GE(db, kMinPsnr) << backend << ", " << trace_mode_name(mode);
  EXPECT_EQ(acne_pixels(reference.image, moved.image), 0) << backend;
}

/// Every mesh an instance at 1e9 (world transforms in double, instance transforms written
/// relative to the render origin in float).
TEST_P(LargeWorld, InstancesAt1e9RenderLikeAtTheOrigin) {
  const auto& [backend, mode] = GetParam();
  Scene at_origin = load_sample("mirror_spheres_1");
  make_every_mesh_an_instance(at_origin.registry);
  const Frame reference = render(at_origin, backend, mode);
  ASSERT_EQ(reference.layer.static_instances, 0u);

  Scene far = load_sample("mirror_spheres_1");
  make_every_mesh_an_instance(far.registry);
  translate_world(far.registry, dvec3(-1e9, 2e8, 1e9));
  const Frame moved = render(far, backend, mode);
  EXPECT_EQ(moved.layer.static_instances, 0u);
  EXPECT_GT(moved.layer.dynamic_instances, 0u);

  const double db = psnr(reference.image, moved.image);
  EXPECT_GE(db, kMinPsnr) << backend << ", " << trace_mode_name(mode);
  EXPECT_EQ(acne_pixels(reference.image, moved.image), 0) << backend;
}

/// A camera path that carries the camera 5000 units away and back in two ticks rebases the render
/// origin twice, and the frame after it is the frame of the scene rendered fresh (whose origin is
/// the same camera position): a rebase leaves no trace in the image. The spheres are instances,
/// the ground static, so both kinds are rewritten.
TEST_P(LargeWorld, ARebaseRendersLikeAFreshStart) {
  const auto& [backend, mode] = GetParam();
  const dvec3 offset(1e7, 0.0, -1e7), step(5000.0, 0.0, 0.0);
  const auto make = [&] {
    Scene scene = load_sample("mirror_spheres_1");
    scene.registry.view<Mesh, Name>().each([&](ecs::Entity e, const Mesh&, const Name& n) {
      if (n.value != "ground")
        scene.registry.emplace_or_replace<Kinematics>(e,
                                                      Kinematics{Kinematics::Type::Hierarchical});
    });
    translate_world(scene.registry, offset);
    return scene;
  };
  Scene flying = make();
  const ecs::Entity cam = flying.registry.view<Camera>().entities().front();
  const Camera start = flying.registry.get<Camera>(cam);
  CameraPath path;
  path.loop = false;
  path.keys = {{0.0f, start.position, start.look_at},
               {1.0f, start.position + step, start.look_at + step},
               {2.0f, start.position, start.look_at}};
  flying.registry.emplace<CameraPath>(cam, path);

  test::prepare_scene_render(flying, mode, backend, kSize, kSize);
  Schedule schedule;
  schedule.tick(flying.registry, 0.0); // at the start: the first sync puts the origin there
  schedule.tick(flying.registry, 1.0); // 5000 away: past kRebaseDistance
  schedule.tick(flying.registry, 1.0); // and back
  const SceneLayer& layer = flying.registry.resource<SceneLayer>();
  EXPECT_EQ(layer.rebases(), 2u);
  EXPECT_EQ(layer.render_origin(), start.position);

  Scene fresh_scene = make();
  const Frame fresh = render(fresh_scene, backend, mode);
  EXPECT_EQ(fresh.render_origin, layer.render_origin());
  const Framebuffer& after = flying.registry.resource<RenderJob>().image;
  EXPECT_EQ(rmse(after, fresh.image), 0.0) << "the same render space, the same image";
  float darkest = 1.0f, brightest = 0.0f; // the scene is in view, not just the background
  for (std::uint32_t y = 0; y < kSize; ++y)
    for (std::uint32_t x = 0; x < kSize; ++x) {
      darkest = std::min(darkest, luminance(after.at(x, y)));
      brightest = std::max(brightest, luminance(after.at(x, y)));
    }
  EXPECT_GT(brightest - darkest, 0.3f);
}

INSTANTIATE_TEST_SUITE_P(Backends, LargeWorld,
                         ::testing::Combine(::testing::ValuesIn(test::available_backends()),
                                            ::testing::Values(TraceMode::Whitted, TraceMode::Cast)),
                         [](const auto& param_info) {
                           return test::test_name(std::get<0>(param_info.param)) + "_" +
                                  trace_mode_name(std::get<1>(param_info.param));
                         });

// --- The representable range ------------------------------------------------------------------

class CoordinateRange : public ::testing::TestWithParam<std::string> {};

/// A camera just inside the range, looking at a box whose vertices reach 5e11 on the way: every
/// render-space coordinate stays far inside what the backends accept, and every pixel is finite.
TEST_P(CoordinateRange, ScenesJustInsideTheRangeRenderFinitePixels) {
  for (const dvec3 camera_at : {dvec3(0.0, 0.0, 0.999e12), dvec3(0.999e12, -0.999e12, 0.999e12)}) {
    ecs::Registry reg;
    // A box with 1e12 edges at the origin, and a small sphere just inside the corner of the range.
    test::add_mesh(reg, test::primitive("box", 1.0f, vec3(1e12f)), test::at(vec3(0.0f)));
    Transform near_corner;
    near_corner.translation = camera_at - dvec3(0.0, 0.0, 10.0);
    test::add_mesh(reg, test::primitive("sphere", 1.0f), near_corner, Material{},
                   Kinematics::Type::Hierarchical);
    Transform light;
    light.translation = camera_at + dvec3(1.0, 1.0, 0.0);
    const ecs::Entity l = reg.create();
    reg.emplace<Transform>(l, light);
    reg.emplace<Light>(l, Light{});
    const ecs::Entity c = reg.create();
    Camera cam;
    cam.position = camera_at;
    cam.look_at = camera_at - dvec3(0.0, 0.0, 1.0);
    reg.emplace<Camera>(c, cam);
    update_world_transforms(reg, 0);

    RenderJob job;
    job.backend = GetParam();
    job.settings.threads = 2;
    job.image = Framebuffer(16, 16);
    prepare_rendering(reg, std::move(job));
    Schedule schedule;
    schedule.tick(reg, 0.0);
    const Framebuffer& image = reg.resource<RenderJob>().image;
    int lit = 0;
    for (std::uint32_t y = 0; y < 16; ++y)
      for (std::uint32_t x = 0; x < 16; ++x) {
        ASSERT_TRUE(is_finite(image.at(x, y))) << "pixel " << x << ", " << y;
        lit += luminance(image.at(x, y)) > 0.0f ? 1 : 0;
      }
    EXPECT_GT(lit, 0) << "the sphere in front of the camera is lit";
  }
}

/// An animation that carries an entity out of the range is an error naming it at that tick, not
/// an abort inside a tracer.
TEST_P(CoordinateRange, AnimationLeavingTheRangeIsAnErrorNamingTheEntity) {
  ecs::Registry reg;
  const ecs::Entity e = test::add_mesh(reg, test::primitive("sphere"), test::at(vec3(0.0f)),
                                       Material{}, Kinematics::Type::Free);
  reg.emplace<Name>(e, "runaway");
  Animation a;
  a.translation.times = {0.0f, 1.0f};
  a.translation.values = {dvec3(0.0), dvec3(0.0, 0.0, 0.9e12)};
  a.loop = false;
  reg.emplace<Animation>(e, a);
  // A parent scale that carries the child's small translation out of the range as it grows.
  const ecs::Entity parent = reg.create();
  reg.emplace<Name>(parent, "grower");
  reg.emplace<Transform>(parent, test::at(vec3(0.0f)));
  Animation grow;
  grow.scale.times = {0.0f, 1.0f};
  grow.scale.values = {vec3(1.0f), vec3(1e8f)};
  grow.loop = false;
  reg.emplace<Animation>(parent, grow);
  const ecs::Entity child =
      test::add_mesh(reg, test::primitive("sphere"), test::at(vec3(0, 0, 1e5f)), Material{},
                     Kinematics::Type::Hierarchical);
  reg.emplace<Name>(child, "child");
  reg.emplace<Parent>(child, Parent{parent});
  test::add_camera(reg, vec3(0, 0, 10), vec3(0.0f));
  update_world_transforms(reg, 0);

  RenderJob job;
  job.backend = GetParam();
  job.settings.threads = 2;
  job.image = Framebuffer(8, 8);
  prepare_rendering(reg, std::move(job));
  Schedule schedule;
  schedule.tick(reg, 0.0); // in range at t = 0
  try {
    schedule.tick(reg, 2.0); // the child at 1e13
    FAIL() << "expected an error";
  } catch (const Error& err) {
    EXPECT_NE(std::string(err.what()).find("\"child\""), std::string::npos) << err.what();
    EXPECT_NE(std::string(err.what()).find("outside the representable range"), std::string::npos)
        << err.what();
  }
}

/// A mesh whose scale carries its vertices out of the range (its origin stays inside) is an
/// error naming it when the scene layer writes it.
TEST_P(CoordinateRange, ScaledExtentLeavingTheRangeIsAnErrorNamingTheEntity) {
  ecs::Registry reg;
  const ecs::Entity e = test::add_mesh(reg, test::primitive("sphere", 1e5f), test::at(vec3(0.0f)),
                                       Material{}, Kinematics::Type::Hierarchical);
  reg.emplace<Name>(e, "balloon");
  test::add_camera(reg, vec3(0, 0, 10), vec3(0.0f));
  update_world_transforms(reg, 0);
  RenderJob job;
  job.backend = GetParam();
  job.settings.threads = 2;
  job.image = Framebuffer(8, 8);
  prepare_rendering(reg, std::move(job));
  Schedule schedule;
  schedule.tick(reg, 0.0);
  reg.get<Transform>(e).scale = vec3(1e8f); // vertices at 1e13
  try {
    schedule.tick(reg, 0.0);
    FAIL() << "expected an error";
  } catch (const Error& err) {
    EXPECT_NE(std::string(err.what()).find("\"balloon\" extends from"), std::string::npos)
        << err.what();
  }
}

INSTANTIATE_TEST_SUITE_P(Backends, CoordinateRange, ::testing::ValuesIn(test::available_backends()),
                         [](const auto& param_info) { return test::test_name(param_info.param); });

} // namespace
} // namespace specula
