// Properties of rendered frames and of the Whitted integrator's rays (on the default backend; the
// conformance suite runs the backend-specific properties on every backend).

#include "scene_builder.h"
#include "specula/core/error.h"
#include "specula/render/render_job.h"
#include "specula/scene/scene.h"
#include "specula/systems/schedule.h"
#include "specula/trace/lights.h"
#include "specula/trace/shading.h"

#include <xmmintrin.h>

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <random>

namespace specula {
namespace {

Framebuffer render(ecs::Registry& reg, TraceMode mode, std::uint32_t size,
                   std::uint32_t threads = 2, std::uint32_t packet = 16, std::uint32_t tile = 16) {
  RenderJob job;
  job.settings.mode = mode;
  job.settings.threads = threads;
  job.settings.tile_size = tile;
  job.packet_width = packet;
  job.image = Framebuffer(size, size);
  prepare_rendering(reg, std::move(job));
  Schedule schedule;
  schedule.tick(reg, 0.0);
  return reg.resource<RenderJob>().image;
}

/// A closed diffuse box (seen from inside) with a point light and the camera inside it, scaled by
/// `scale` and moved to `center`.
void closed_box(ecs::Registry& reg, float scale, const vec3& center) {
  test::add_mesh(reg, test::primitive("box", 1.0f, vec3(4.0f)), test::at(center, vec3(scale)));
  // A sphere on the floor: its own shadow is inside the box too (the light must still reach
  // every wall point it can see directly).
  test::add_point_light(reg, center + scale * vec3(0.5f, 1.2f, 0.3f), scale * scale * 4.0f);
  test::add_camera(reg, center + scale * vec3(0.0f, 0.0f, 1.8f),
                   center + scale * vec3(0.1f, -0.2f, -2.0f), 100.0f);
}

/// A tessellated sphere and a box hovering just above a large plane, lit by a light at the camera
/// ("headlight"): every point the camera sees is visible from the light, so any shadowed pixel
/// is acne. They hover (2% of their size) rather than touch: in a contact crease two surfaces come
/// closer than any offset can resolve, which is a different limit (docs/design/ray-offsets.md).
void headlight_scene(ecs::Registry& reg, float scale, const vec3& center) {
  test::add_mesh(reg, test::primitive("plane", 1.0f, vec3(40.0f), 3, 20),
                 test::at(center, vec3(scale)));
  test::add_mesh(reg, test::primitive("sphere", 1.0f, vec3(1), 48, 24),
                 test::at(center + scale * vec3(0, 1.02f, 0), vec3(scale)));
  test::add_mesh(reg, test::primitive("box", 1.0f, vec3(1.5f)),
                 test::at(center + scale * vec3(-2.5f, 0.78f, 0.5f), vec3(scale),
                          glm::angleAxis(0.6f, vec3(0, 1, 0))));
  const vec3 eye = center + scale * vec3(1.5f, 2.5f, 6.0f);
  test::add_camera(reg, eye, center + scale * vec3(-0.5f, 0.5f, 0.0f), 50.0f);
  test::add_point_light(reg, eye, scale * scale * 40.0f);
}

/// Pixels darker with shadow rays than without, where nothing can truly be in shadow.
int count_shadowed_pixels(const Framebuffer& with_shadows, const Framebuffer& without) {
  int n = 0;
  for (std::size_t i = 0; i < with_shadows.pixel_count(); ++i) {
    const vec3 a = with_shadows.pixels()[i];
    const vec3 b = without.pixels()[i];
    if (a.x < b.x * (1.0f - 1e-4f) || a.y < b.y * (1.0f - 1e-4f) || a.z < b.z * (1.0f - 1e-4f)) ++n;
  }
  return n;
}

struct Scale {
  float scale;
  vec3 center;
};
const Scale kScales[] = {{1.0f, vec3(0.0f)},
                         {1e5f, vec3(1e5f, -2e5f, 1e5f)},
                         {1e-3f, vec3(0.0f)},
                         {1e-3f, vec3(3.0f, 1.0f, -2.0f)}};

TEST(Render, PointLightInsideAClosedBoxLightsEveryPixel) {
  for (const Scale& s : kScales) {
    ecs::Registry lit, unshadowed;
    closed_box(lit, s.scale, s.center);
    closed_box(unshadowed, s.scale, s.center);
    const Framebuffer whitted = render(lit, TraceMode::Whitted, 96);
    const Framebuffer cast = render(unshadowed, TraceMode::Cast, 96);
    int dark = 0;
    for (const vec3& p : whitted.pixels()) dark += (p.x > 0.0f && p.y > 0.0f && p.z > 0.0f) ? 0 : 1;
    EXPECT_EQ(dark, 0) << "scale " << s.scale;
    // In a convex room nothing is in shadow: shadow rays must change no pixel.
    EXPECT_EQ(count_shadowed_pixels(whitted, cast), 0) << "scale " << s.scale;
  }
}

TEST(Render, NoShadowAcneOnUnitLargeFarAndTinyScenes) {
  // Not the tiny-and-far case: a 1 mm object 3 m from the origin sits where float spacing is
  // 0.02% of its size, and headlight rays grazing its silhouette flip (docs/design/ray-offsets.md).
  for (const Scale& s : {kScales[0], kScales[1], kScales[2]}) {
    ecs::Registry a, b;
    headlight_scene(a, s.scale, s.center);
    headlight_scene(b, s.scale, s.center);
    const Framebuffer whitted = render(a, TraceMode::Whitted, 160);
    const Framebuffer cast = render(b, TraceMode::Cast, 160);
    EXPECT_EQ(count_shadowed_pixels(whitted, cast), 0)
        << "scale " << s.scale << " centre " << s.center.x;
    int lit = 0;
    for (const vec3& p : whitted.pixels()) lit += p.x > 0.0f ? 1 : 0;
    EXPECT_GT(lit, 160 * 160 / 2) << "the scene must fill the frame for the test to mean something";
  }
}

TEST(Render, ShadowsAreCastWhereTheyShouldBe) {
  // The counterpart of the acne test: with the light above, the sphere does shadow the plane.
  ecs::Registry a, b;
  for (ecs::Registry* reg : {&a, &b}) {
    test::add_mesh(*reg, test::primitive("plane", 1.0f, vec3(40.0f)), test::at(vec3(0)));
    test::add_mesh(*reg, test::primitive("sphere", 1.0f), test::at(vec3(0, 1.5f, 0)));
    test::add_camera(*reg, vec3(0, 6, 6), vec3(0), 50.0f);
    test::add_point_light(*reg, vec3(0, 8, 0), 100.0f);
  }
  const Framebuffer whitted = render(a, TraceMode::Whitted, 64);
  const Framebuffer cast = render(b, TraceMode::Cast, 64);
  EXPECT_GT(count_shadowed_pixels(whitted, cast), 20);
}

/// A world with a slab of glass: 4 × 0.5 × 4 at the origin.
ecs::Registry& glass_slab(ecs::Registry& reg) {
  Material glass;
  glass.base_color = vec3(1.0f);
  glass.transmission = 1.0f;
  glass.ior = 1.5f;
  test::add_mesh(reg, test::primitive("box", 1.0f, vec3(4.0f, 0.5f, 4.0f)), test::at(vec3(0)),
                 glass);
  return reg;
}

const gpu::GpuMaterial& material_of(const test::TracedWorld& world, const Hit& hit) {
  return world.tables().materials[world.tables().instances[hit.instance].material];
}

/// Follows the refracted branch of the integrator's split through the scene.
struct Step {
  ShadingPoint sp;
  SpecularSplit split;
  Ray next;
};
Step follow_refraction(const test::TracedWorld& world, const Ray& ray) {
  const Hit hit = world.intersect(ray);
  EXPECT_TRUE(hit.hit());
  Step step;
  step.sp = shading_point(world.tables(), hit, ray.direction);
  step.split = split_specular(material_of(world, hit), step.sp, ray.direction);
  step.next.origin =
      offset_ray_origin(step.sp.spawn_point, step.sp.spawn_error, -step.sp.geometric_normal);
  step.next.direction = step.split.refract_direction;
  return step;
}

TEST(Render, ARayThroughAGlassSlabExitsParallelToItsEntry) {
  ecs::Registry reg;
  const test::TracedWorld world(glass_slab(reg));
  for (const float degrees : {0.0f, 10.0f, 30.0f, 60.0f, 80.0f}) {
    const float theta = glm::radians(degrees);
    Ray ray;
    ray.direction = vec3(std::sin(theta), -std::cos(theta), 0.0f);
    ray.origin = vec3(-0.5f, 0.25f, 0.1f) - 3.0f * ray.direction; // aimed at the top face
    const Step in = follow_refraction(world, ray);
    ASSERT_GT(in.split.refract_weight, 0.0f);
    EXPECT_TRUE(in.sp.front_face);
    const Step out = follow_refraction(world, in.next);
    ASSERT_GT(out.split.refract_weight, 0.0f) << degrees;
    EXPECT_FALSE(out.sp.front_face);
    EXPECT_NEAR(glm::dot(out.split.refract_direction, ray.direction), 1.0f, 1e-5f) << degrees;
    // Lateral shift of a slab of thickness h: h·sin(θi − θt) / cos θt.
    const float theta_t = std::asin(std::sin(theta) / 1.5f);
    const float shift = 0.5f * std::sin(theta - theta_t) / std::cos(theta_t);
    const vec3 exit = out.sp.position;
    const vec3 straight = ray.origin + ray.direction * (glm::dot(exit - ray.origin, ray.direction));
    EXPECT_NEAR(glm::length(exit - straight), shift, 1e-4f) << degrees;
    // Energy: what is not reflected goes on.
    EXPECT_NEAR(in.split.reflect_weight + in.split.refract_weight, 1.0f, 1e-6f);
  }
}

TEST(Render, TotalInternalReflectionBeyondTheCriticalAngle) {
  ecs::Registry reg;
  const test::TracedWorld world(glass_slab(reg));
  const float critical = std::asin(1.0f / 1.5f);
  for (const float delta : {0.02f, 0.2f, 0.5f}) {
    const float theta = critical + delta;
    Ray ray; // inside the slab, heading up to the top face
    ray.origin = vec3(0.0f, 0.0f, 0.0f);
    ray.direction = vec3(std::sin(theta), std::cos(theta), 0.0f);
    const Hit hit = world.intersect(ray);
    ASSERT_TRUE(hit.hit());
    const auto sp = shading_point(world.tables(), hit, ray.direction);
    EXPECT_FALSE(sp.front_face);
    const auto split = split_specular(material_of(world, hit), sp, ray.direction);
    EXPECT_EQ(split.refract_weight, 0.0f) << delta;
    EXPECT_EQ(split.reflect_weight, 1.0f) << delta;
    EXPECT_NEAR(split.reflect_direction.y, -ray.direction.y, 1e-5f);
    EXPECT_NEAR(split.reflect_direction.x, ray.direction.x, 1e-5f);
  }
  // Just below the critical angle some light gets out.
  Ray ray;
  ray.direction = vec3(std::sin(critical - 0.02f), std::cos(critical - 0.02f), 0.0f);
  const Hit hit = world.intersect(ray);
  ASSERT_TRUE(hit.hit());
  const auto split = split_specular(
      material_of(world, hit), shading_point(world.tables(), hit, ray.direction), ray.direction);
  EXPECT_GT(split.refract_weight, 0.0f);
}

TEST(Render, ReflectionOffAMirrorPreservesTheAngle) {
  ecs::Registry reg;
  Material mirror;
  mirror.reflectivity = 1.0f;
  test::add_mesh(reg, test::primitive("sphere", 2.0f, vec3(1), 64, 32), test::at(vec3(0)), mirror);
  const test::TracedWorld world(reg);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1.3f, 1.3f); // inside the tessellated outline
  for (int i = 0; i < 500; ++i) {
    Ray ray;
    ray.origin = vec3(u(rng), u(rng), 10.0f);
    ray.direction = vec3(0, 0, -1);
    const Hit hit = world.intersect(ray);
    ASSERT_TRUE(hit.hit());
    const auto sp = shading_point(world.tables(), hit, ray.direction);
    const auto split = split_specular(material_of(world, hit), sp, ray.direction);
    EXPECT_EQ(split.reflect_weight, 1.0f);
    EXPECT_EQ(split.refract_weight, 0.0f);
    EXPECT_NEAR(glm::dot(split.reflect_direction, sp.shading_normal),
                -glm::dot(ray.direction, sp.shading_normal), 1e-5f);
    EXPECT_GT(glm::dot(split.reflect_direction, sp.geometric_normal), 0.0f); // leaves the surface
  }
}

ecs::Registry& cornell(ecs::Registry& reg) {
  // Diffuse walls, a mirror sphere and a glass sphere: every ray kind appears.
  Material white, red, mirror, glass;
  red.base_color = vec3(0.7f, 0.1f, 0.1f);
  mirror.reflectivity = 0.9f;
  glass.transmission = 0.95f;
  glass.ior = 1.5f;
  test::add_mesh(reg, test::primitive("box", 1.0f, vec3(4.0f)), test::at(vec3(0, 2, 0)), white);
  test::add_mesh(reg, test::primitive("box", 1.0f, vec3(0.2f, 4.0f, 4.0f)),
                 test::at(vec3(-1.9f, 2, 0)), red);
  test::add_mesh(reg, test::primitive("sphere", 0.7f), test::at(vec3(-0.8f, 0.7f, -0.5f)), mirror);
  test::add_mesh(reg, test::primitive("sphere", 0.6f), test::at(vec3(0.9f, 0.6f, 0.4f)), glass);
  test::add_point_light(reg, vec3(0, 3.6f, 0), 8.0f);
  test::add_camera(reg, vec3(0, 2, 1.9f), vec3(0, 1.5f, -2), 70.0f);
  return reg;
}

TEST(Render, ImagesAreBitIdenticalWhateverTheThreadCountTileOrPacketWidth) {
  ecs::Registry a, b, c, d;
  const Framebuffer one = render(cornell(a), TraceMode::Whitted, 80, 1, 16, 16);
  const Framebuffer two = render(cornell(b), TraceMode::Whitted, 80, 2, 16, 16);
  const Framebuffer small_tiles = render(cornell(c), TraceMode::Whitted, 80, 2, 4, 8);
  const Framebuffer single_rays = render(cornell(d), TraceMode::Whitted, 80, 2, 1, 16);
  EXPECT_TRUE(one == two);
  EXPECT_TRUE(one == small_tiles);
  EXPECT_TRUE(one == single_rays);
  EXPECT_TRUE(a.resource<RenderJob>().last.rays == b.resource<RenderJob>().last.rays);
}

TEST(Render, TheCallersFloatingPointModeIsLeftAsItWas) {
  // Tracing flushes denormals for Embree; the calling thread must get its own mode back.
  // The mode bits only: the sticky exception flags (bits 0–5) record any inexact arithmetic the
  // caller's thread did, such as building the native backend's structures.
  constexpr unsigned int kModeBits = ~0x3Fu;
  const unsigned int before = _mm_getcsr() & kModeBits;
  ecs::Registry reg;
  render(cornell(reg), TraceMode::Whitted, 32, 1);
  EXPECT_EQ(_mm_getcsr() & kModeBits, before);
  volatile float tiny = 1e-39f; // a denormal must survive arithmetic on this thread
  EXPECT_GT(tiny * 1.0f, 0.0f);
}

/// Static and moving objects under every kind of light: point, point with a range, spot and
/// directional, two of them coloured.
void lit_by_every_light(ecs::Registry& reg, Kinematics::Type objects) {
  Material red, glow;
  red.base_color = vec3(0.8f, 0.2f, 0.1f);
  glow.emission = vec3(0.3f, 0.2f, 0.1f);
  test::add_mesh(reg, test::primitive("plane", 1.0f, vec3(20.0f)), test::at(vec3(0)));
  test::add_mesh(reg, test::primitive("sphere", 1.0f, vec3(1), 48, 24), test::at(vec3(0, 1, 0)), red, objects);
  test::add_mesh(reg, test::primitive("box", 1.0f, vec3(1, 2, 1)),
                 test::at(vec3(-2.5f, 1, 0.5f), vec3(1), glm::angleAxis(0.5f, vec3(0, 1, 0))), glow, objects);
  test::add_point_light(reg, vec3(2, 5, 3), 30.0f);
  const ecs::Entity ranged = test::add_point_light(reg, vec3(-3, 3, 2), 20.0f);
  reg.get<Light>(ranged).range = 6.0f;
  reg.get<Light>(ranged).color = vec3(0.2f, 0.6f, 1.0f);
  const ecs::Entity spot = test::add_point_light(reg, vec3(0, 6, 0), 40.0f);
  reg.get<Light>(spot).type = Light::Type::Spot;
  reg.get<Light>(spot).outer_cone = 0.5f;
  reg.get<Transform>(spot).rotation = rotation_looking_along(vec3(0, -1, 0.2f));
  const ecs::Entity sun = test::add_point_light(reg, vec3(0), 0.4f);
  reg.get<Light>(sun).type = Light::Type::Directional;
  reg.get<Light>(sun).color = vec3(1.0f, 0.9f, 0.7f);
  reg.get<Transform>(sun).rotation = rotation_looking_along(vec3(-0.3f, -1, -0.4f));
  test::add_camera(reg, vec3(1, 4, 8), vec3(0, 0.5f, 0), 50.0f);
}

TEST(Render, CastModeIsTheShadingFormulaAtEveryPixel) {
  // The cast integrator runs vectorised kernels over the wave; here every pixel is compared with
  // the plain formula: shading_point, then emission plus each light's sample_light term.
  for (const Kinematics::Type kind : {Kinematics::Type::Static, Kinematics::Type::Free}) {
    ecs::Registry reg;
    lit_by_every_light(reg, kind);
    const std::uint32_t size = 64;
    const Framebuffer image = render(reg, TraceMode::Cast, size);
    const SceneLayer& layer = reg.resource<SceneLayer>();
    const SceneTables& tables = layer.tables();
    const Tracer& tracer = *reg.resource<ActiveTracer>().tracer;
    const CameraRays camera(*active_camera(reg), size, size);
    int compared = 0;
    for (std::uint32_t y = 0; y < size; ++y)
      for (std::uint32_t x = 0; x < size; ++x) {
        const Ray ray = camera.ray(x, y);
        Hit hit;
        tracer.intersect(std::span<const Ray>(&ray, 1), std::span<Hit>(&hit, 1));
        vec3 expected(0.0f); // background
        if (hit.hit()) {
          const ShadingPoint sp = shading_point(tables, hit, ray.direction, false);
          const gpu::GpuMaterial& m = tables.materials[tables.instances[hit.instance].material];
          vec3 lights(0.0f);
          for (const gpu::GpuLight& light : tables.lights) {
            const LightSample ls = sample_light(light, sp.position);
            const float cos_theta = glm::dot(ls.to_light, sp.shading_normal);
            if (glm::dot(ls.to_light, sp.geometric_normal) > 0.0f && cos_theta > 0.0f &&
                max_component(ls.irradiance) > 0.0f)
              lights += m.base_color * std::numbers::inv_pi_v<float> * ls.irradiance * cos_theta;
          }
          expected = m.emission + lights;
          ++compared;
        }
        const vec3 got = image.pixels()[std::size_t(y) * size + x];
        ASSERT_LE(glm::length(got - expected), 1e-5f * (1.0f + glm::length(expected)))
            << "pixel " << x << "," << y << (kind == Kinematics::Type::Free ? " (moving objects)" : "");
      }
    EXPECT_GT(compared, int(size * size / 2));
  }
}

TEST(Render, RayCountsFollowTheMode) {
  ecs::Registry a, b;
  const std::uint32_t size = 64;
  render(cornell(a), TraceMode::Cast, size);
  const RayCounts cast = a.resource<RenderJob>().last.rays;
  EXPECT_EQ(cast[RayKind::Primary], size * size);
  EXPECT_EQ(cast[RayKind::Shadow] + cast[RayKind::Reflection] + cast[RayKind::Refraction], 0u);
  render(cornell(b), TraceMode::Whitted, size);
  const RayCounts whitted = b.resource<RenderJob>().last.rays;
  EXPECT_EQ(whitted[RayKind::Primary], size * size);
  EXPECT_GT(whitted[RayKind::Shadow], 0u);
  EXPECT_GT(whitted[RayKind::Reflection], 0u);
  EXPECT_GT(whitted[RayKind::Refraction], 0u);
}

TEST(Render, NoShadowRaysWithoutLights) {
  ecs::Registry reg;
  cornell(reg);
  const auto lights = reg.view<Light>().entities();
  for (const ecs::Entity e : lights) reg.destroy(e);
  render(reg, TraceMode::Whitted, 32);
  EXPECT_EQ(reg.resource<RenderJob>().last.rays[RayKind::Shadow], 0u);
}

TEST(Render, MaxDepthBoundsTheBounces) {
  // Two parallel mirrors facing each other: without the depth limit the ray would bounce forever.
  Material mirror;
  mirror.reflectivity = 1.0f;
  for (const std::uint32_t depth : {0u, 1u, 5u, 12u}) {
    ecs::Registry r2;
    test::add_mesh(r2, test::primitive("box", 1.0f, vec3(0.1f, 10, 10)), test::at(vec3(-2, 0, 0)),
                   mirror);
    test::add_mesh(r2, test::primitive("box", 1.0f, vec3(0.1f, 10, 10)), test::at(vec3(2, 0, 0)),
                   mirror);
    test::add_camera(r2, vec3(0, 0, 0), vec3(-1, 0, 0.001f), 10.0f);
    RenderJob job;
    job.settings.max_depth = depth;
    job.settings.min_weight = 0.0f;
    job.image = Framebuffer(8, 8);
    prepare_rendering(r2, std::move(job));
    Schedule schedule;
    schedule.tick(r2, 0.0);
    EXPECT_EQ(r2.resource<RenderJob>().last.rays[RayKind::Reflection], 64u * depth) << depth;
  }
}

TEST(Render, TheDepthLimitOfScenesIsTheRenderJobs) {
  // Scene loaders accept max_depth up to kMaxTraceDepth; the job takes every such depth (the
  // wave integrator has no recursion) and honours it: facing mirrors, one bounce per level.
  Material mirror;
  mirror.reflectivity = 1.0f;
  for (const std::uint32_t depth : {kMaxTraceDepth, kMaxTraceDepth + 1}) {
    ecs::Registry r2;
    test::add_mesh(r2, test::primitive("box", 1.0f, vec3(0.1f, 10, 10)), test::at(vec3(-2, 0, 0)),
                   mirror);
    test::add_mesh(r2, test::primitive("box", 1.0f, vec3(0.1f, 10, 10)), test::at(vec3(2, 0, 0)),
                   mirror);
    // A narrow view, so that no pixel's ray walks off the 10-unit mirrors in 64 bounces.
    test::add_camera(r2, vec3(0, 0, 0), vec3(-1, 0, 0.001f), 0.5f);
    RenderJob job;
    job.settings.max_depth = depth;
    job.settings.min_weight = 0.0f;
    job.image = Framebuffer(2, 2);
    if (depth > kMaxTraceDepth) {
      EXPECT_THROW(prepare_rendering(r2, std::move(job)), Error);
      continue;
    }
    prepare_rendering(r2, std::move(job));
    Schedule schedule;
    schedule.tick(r2, 0.0);
    EXPECT_EQ(r2.resource<RenderJob>().last.rays[RayKind::Reflection], 4u * depth);
  }
}

} // namespace
} // namespace specula
