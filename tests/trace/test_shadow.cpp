// The shadow caster (--mode shadow): soft shadows of area lights against the analytic penumbra,
// point-light shadows identical to Whitted's, determinism, the gain of stratified samples, and the
// vectorised area-light samples against the scalar ones.

#include "scene_builder.h"
#include "specula/render/render_job.h"
#include "specula/systems/schedule.h"
#include "specula/trace/camera_rays.h"
#include "specula/trace/render_frame.h"
#include "specula/trace/shading.h"
#include "specula/trace/shadow_samples.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <numbers>
#include <random>
#include <vector>

namespace specula {
namespace {

struct Options {
  std::uint32_t width = 65, height = 65;
  std::uint32_t threads = 2, tile = 16, packet = 16;
};

Framebuffer render(ecs::Registry& reg, TraceSettings settings, const Options& o = {}) {
  RenderJob job;
  settings.threads = o.threads;
  settings.tile_size = o.tile;
  job.settings = settings;
  job.packet_width = o.packet;
  job.image = Framebuffer(o.width, o.height);
  prepare_rendering(reg, std::move(job));
  Schedule schedule;
  schedule.tick(reg, 0.0);
  return reg.resource<RenderJob>().image;
}

TraceSettings shadow_settings(std::uint32_t samples, std::uint32_t seed = 0) {
  TraceSettings s;
  s.mode = TraceMode::Shadow;
  s.shadow_samples = samples;
  s.seed = seed;
  return s;
}

/// A square emitter of width kW at height kH over a white ground, and a zero-thickness occluder
/// (a plane) covering x < 0 at height kh: its edge, along z, is parallel to the light's. The
/// penumbra on the ground spans x ∈ [−P/2, P/2], P = kW·kh / (kH − kh), umbra for x < −P/2.
constexpr float kW = 1.0f, kH = 4.0f, kh = 1.0f, kEmission = 10.0f;
constexpr float kPenumbra = kW * kh / (kH - kh);

/// The camera looks at the ground obliquely from the lit side (+x), under the occluder's edge: the
/// image's centre column runs along the ground's x axis (z = 0) across the whole penumbra.
Camera penumbra_camera(float fov_degrees) {
  Camera c;
  c.position = dvec3(3.0, 3.0, 0.0);
  c.look_at = dvec3(0.0);
  c.vertical_fov = glm::radians(fov_degrees);
  return c;
}

void penumbra_scene(ecs::Registry& reg, float fov_degrees = 12.0f) {
  Material white;
  white.base_color = vec3(1.0f);
  test::add_mesh(reg, test::primitive("plane", 1.0f, vec3(20.0f)), test::at(vec3(0.0f)), white);
  test::add_mesh(reg, test::primitive("plane", 1.0f, vec3(4.0f)), test::at(vec3(-2.0f, kh, 0.0f)),
                 white);
  Material glow;
  glow.base_color = vec3(0.0f);
  glow.emission = vec3(kEmission);
  // One quad (two triangles): the light's samples are stratified over the CDF of its triangles,
  // which for a quad is stratification over its area (shadow_integrator.cpp).
  test::add_mesh(reg, test::primitive("plane", 1.0f, vec3(kW), 32, 1),
                 test::at(vec3(0.0f, kH, 0.0f)), glow);
  const ecs::Entity e = reg.create();
  reg.emplace<Camera>(e, penumbra_camera(fov_degrees));
}

/// Radiance of the white ground at (x, 0, 0) lit by the part of the light with light-x ≥ from:
/// (1/π) ∫ L_e cos θ cos θ_l / r² dA by the midpoint rule.
double ground_radiance(double x, double from) {
  constexpr int kSteps = 200;
  const double lo = std::max(from, -0.5 * kW), hi = 0.5 * kW;
  if (lo >= hi) return 0.0;
  const double dx = (hi - lo) / kSteps, dz = double(kW) / kSteps;
  double sum = 0.0;
  for (int i = 0; i < kSteps; ++i)
    for (int j = 0; j < kSteps; ++j) {
      const double lx = lo + (i + 0.5) * dx - x, lz = -0.5 * kW + (j + 0.5) * dz;
      const double r2 = lx * lx + lz * lz + double(kH) * kH;
      sum += double(kH) * kH / (r2 * r2); // cos θ = cos θ_l = H / r
    }
  return kEmission * sum * dx * dz / std::numbers::pi;
}

/// The ground's x at the centre of pixel row y of the centre column (width odd: exactly z = 0).
double ground_x(const Camera& camera, const Options& o, std::uint32_t y) {
  const Ray r = CameraRays(camera, o.width, o.height).ray(o.width / 2, y);
  const double t = -double(r.origin.y) / r.direction.y;
  return double(r.origin.x) + t * r.direction.x;
}

/// Where, going along x, the measured fraction of the unshadowed radiance first reaches `level`
/// (linear interpolation between pixel centres).
double crossing(const std::vector<double>& x, const std::vector<double>& fraction, double level) {
  for (std::size_t k = 1; k < x.size(); ++k)
    if (fraction[k - 1] < level && fraction[k] >= level)
      return x[k - 1] +
             (level - fraction[k - 1]) / (fraction[k] - fraction[k - 1]) * (x[k] - x[k - 1]);
  return std::nan("");
}

TEST(Shadow, PenumbraWidthMatchesTheAnalyticValue) {
  ecs::Registry reg;
  penumbra_scene(reg);
  const Options o{65, 129};
  const Framebuffer image = render(reg, shadow_settings(256), o);
  const Camera camera = penumbra_camera(12.0f);
  // The centre column, ordered by increasing ground x (the top row is farthest from the camera).
  std::vector<double> xs, fraction;
  for (std::uint32_t y = 0; y < o.height; ++y) {
    const double x = ground_x(camera, o, y);
    xs.push_back(x);
    fraction.push_back(image.pixels()[std::size_t(y) * o.width + o.width / 2].x /
                       ground_radiance(x, -1e9));
  }
  ASSERT_LT(xs.front(), -kPenumbra) << "the column must start in the umbra";
  ASSERT_GT(xs.back(), kPenumbra) << "and end fully lit";
  // Umbra and full light away from the ramp (one pixel's footprint inside the analytic bounds).
  const double pixel = (xs.back() - xs.front()) / double(xs.size() - 1); // mean footprint
  for (std::size_t k = 0; k < xs.size(); ++k) {
    if (xs[k] < -0.5 * kPenumbra - pixel) {
      EXPECT_LT(fraction[k], 0.01) << "umbra at x " << xs[k];
    }
    if (xs[k] > 0.5 * kPenumbra + pixel) {
      EXPECT_NEAR(fraction[k], 1.0, 0.01) << "lit at x " << xs[k];
    }
  }
  // The visible part of the light shrinks linearly across the penumbra, so 10 % and 90 % of the
  // full radiance lie 0.8 P apart. Tolerance: the crossings are interpolated between pixel
  // centres (a footprint is ≈ P / 30 here, and the ramp is linear, so interpolation errs far less
  // than one; allowed: half a footprint each), the ramp's departure from linearity (cos θ /r²
  // varies by ≈ 1.5 % over the light: the exact profile below is ≤ 1 % of P off), and 256
  // stratified samples (relative noise ≈ 0.5 % per pixel: ≈ 0.5 % of P per crossing).
  const double x10 = crossing(xs, fraction, 0.1), x90 = crossing(xs, fraction, 0.9);
  ASSERT_TRUE(std::isfinite(x10) && std::isfinite(x90));
  const double measured = (x90 - x10) / 0.8;
  std::printf("penumbra: measured %.4f, analytic %.4f (pixel footprint %.4f)\n", measured,
              double(kPenumbra), pixel);
  EXPECT_NEAR(measured, kPenumbra, pixel + 0.03 * kPenumbra)
      << "10 % at x " << x10 << ", 90 % at x " << x90 << ", pixel " << pixel;
  // The ramp is centred under the occluder's edge.
  EXPECT_NEAR(0.5 * (x10 + x90), 0.0, 0.5 * pixel + 0.03 * kPenumbra);
  // And the rendered profile is the exact one (visible light part l ≥ −x (H − h) / h) within the
  // sample noise, pixel by pixel across the ramp.
  for (std::size_t k = 0; k < xs.size(); ++k) {
    const double exact =
        ground_radiance(xs[k], -xs[k] * (kH - kh) / kh) / ground_radiance(xs[k], -1e9);
    EXPECT_NEAR(fraction[k], exact, 0.02) << "x " << xs[k];
  }
}

/// Diffuse objects, static and moving, under every kind of punctual light, no emitter.
void punctual_scene(ecs::Registry& reg) {
  Material red, grey;
  red.base_color = vec3(0.8f, 0.2f, 0.1f);
  grey.base_color = vec3(0.5f);
  test::add_mesh(reg, test::primitive("plane", 1.0f, vec3(20.0f)), test::at(vec3(0)), grey);
  test::add_mesh(reg, test::primitive("sphere", 1.0f, vec3(1), 48, 24), test::at(vec3(0, 1, 0)),
                 red, Kinematics::Type::Free);
  test::add_mesh(reg, test::primitive("box", 1.0f, vec3(1, 2, 1)),
                 test::at(vec3(-2.5f, 1, 0.5f), vec3(1), glm::angleAxis(0.5f, vec3(0, 1, 0))));
  test::add_mesh(reg, test::primitive("box", 1.0f, vec3(3, 0.2f, 3)), test::at(vec3(2, 3, 1)),
                 Material{}, Kinematics::Type::Free);
  test::add_point_light(reg, vec3(2, 5, 3), 30.0f);
  const ecs::Entity ranged = test::add_point_light(reg, vec3(-3, 3, 2), 20.0f);
  reg.get<Light>(ranged).range = 6.0f;
  reg.get<Light>(ranged).color = vec3(0.2f, 0.6f, 1.0f);
  const ecs::Entity spot = test::add_point_light(reg, vec3(0, 6, 0), 40.0f);
  reg.get<Light>(spot).type = Light::Type::Spot;
  reg.get<Light>(spot).outer_cone = 0.6f;
  reg.get<Light>(spot).inner_cone = 0.3f;
  const ecs::Entity sun = test::add_point_light(reg, vec3(0), 2.0f);
  reg.get<Light>(sun).type = Light::Type::Directional;
  reg.get<Transform>(sun).rotation = glm::angleAxis(-1.0f, vec3(1, 0, 0.3f));
  test::add_camera(reg, vec3(1.5f, 4.0f, 8.0f), vec3(-0.5f, 0.5f, 0.0f), 55.0f);
}

TEST(Shadow, PointLightShadowsAreWhittedsBitForBit) {
  ecs::Registry a, b;
  punctual_scene(a);
  punctual_scene(b);
  TraceSettings whitted;
  whitted.mode = TraceMode::Whitted;
  const Options o{96, 80};
  const Framebuffer reference = render(a, whitted, o);
  const Framebuffer shadow = render(b, shadow_settings(4), o);
  ASSERT_EQ(b.resource<SceneLayer>().emitters().features().area_lights, false);
  std::size_t differ = 0, lit = 0;
  for (std::size_t i = 0; i < reference.pixel_count(); ++i) {
    const vec3 w = reference.pixels()[i], s = shadow.pixels()[i];
    differ += (w.x != s.x || w.y != s.y || w.z != s.z) ? 1 : 0;
    lit += max_component(w) > 0.0f ? 1 : 0;
  }
  EXPECT_EQ(differ, 0u);
  EXPECT_GT(lit, reference.pixel_count() / 2); // the comparison is about lit pixels
  const RayCounts& wr = a.resource<RenderJob>().last.rays;
  const RayCounts& sr = b.resource<RenderJob>().last.rays;
  EXPECT_EQ(sr.count[int(RayKind::Primary)], wr.count[int(RayKind::Primary)]);
  EXPECT_EQ(sr.count[int(RayKind::Shadow)], wr.count[int(RayKind::Shadow)]);
  EXPECT_GT(sr.count[int(RayKind::Shadow)], 0u);
}

/// The penumbra scene with a point light, a mirror sphere and a glass box added.
void mixed_scene(ecs::Registry& reg) {
  penumbra_scene(reg, 60.0f);
  Material mirror, glass;
  mirror.base_color = vec3(0.9f, 0.6f, 0.3f);
  mirror.reflectivity = 0.6f;
  glass.transmission = 0.9f;
  glass.ior = 1.5f;
  test::add_mesh(reg, test::primitive("sphere", 0.4f, vec3(1), 32, 16),
                 test::at(vec3(0.5f, 0.4f, 0.6f)), mirror, Kinematics::Type::Free);
  test::add_mesh(reg, test::primitive("box", 1.0f, vec3(0.5f)), test::at(vec3(0.8f, 0.25f, -0.7f)),
                 glass);
  test::add_point_light(reg, vec3(2.0f, 2.0f, 1.0f), 3.0f);
}

TEST(Shadow, ImagesAreBitIdenticalWhateverTheThreadCountTileOrPacketWidth) {
  TraceSettings s = shadow_settings(8, 5);
  s.sample_offset = 24;
  ecs::Registry a, b, c, d;
  for (ecs::Registry* reg : {&a, &b, &c, &d}) mixed_scene(*reg);
  const Framebuffer one = render(a, s, {64, 48, 1, 16, 16});
  const Framebuffer two = render(b, s, {64, 48, 2, 16, 16});
  const Framebuffer small_tiles = render(c, s, {64, 48, 2, 5, 8});
  const Framebuffer single_rays = render(d, s, {64, 48, 2, 16, 1});
  EXPECT_TRUE(one == two);
  EXPECT_TRUE(one == small_tiles);
  EXPECT_TRUE(one == single_rays);
  const RayCounts& rays = a.resource<RenderJob>().last.rays;
  EXPECT_TRUE(rays == b.resource<RenderJob>().last.rays);
  EXPECT_EQ(rays.count[int(RayKind::Reflection)] + rays.count[int(RayKind::Refraction)], 0u)
      << "no secondary rays";
  EXPECT_EQ(rays.count[int(RayKind::Primary)], 64u * 48u);
  EXPECT_GT(rays.count[int(RayKind::Shadow)], 64u * 48u);
}

TEST(Shadow, GuidesHoldThePrimaryHitsAlbedoNormalAndDepth) {
  ecs::Registry reg;
  Material half_mirror;
  half_mirror.base_color = vec3(0.2f, 0.4f, 0.6f);
  half_mirror.reflectivity = 0.5f;
  test::add_mesh(reg, test::primitive("sphere", 1.0f, vec3(1), 32, 16), test::at(vec3(0)),
                 half_mirror);
  test::add_point_light(reg, vec3(2, 3, 4), 10.0f);
  const ecs::Entity cam = test::add_camera(reg, vec3(0, 0, 4), vec3(0), 40.0f);
  const test::TracedWorld w(reg);
  TraceSettings s = shadow_settings(1);
  s.threads = 2;
  Framebuffer image(24, 20);
  GuideBuffers guides;
  render_frame(*w.tracer, w.layer, reg.get<Camera>(cam), s, image, nullptr, &guides);
  ASSERT_EQ(guides.size(), image.pixel_count());
  const CameraRays rays(reg.get<Camera>(cam), 24, 20, w.layer.render_origin());
  int hits = 0, misses = 0;
  for (std::uint32_t y = 0; y < 20; ++y)
    for (std::uint32_t x = 0; x < 24; ++x) {
      const std::size_t i = std::size_t(y) * 24 + x;
      const Hit hit = w.intersect(rays.ray(x, y));
      if (!hit.hit()) {
        ++misses;
        EXPECT_EQ(guides.albedo[i], vec3(1.0f));
        EXPECT_EQ(guides.normal[i], vec3(0.0f));
        EXPECT_TRUE(std::isinf(guides.depth[i]));
        continue;
      }
      ++hits;
      EXPECT_NEAR(guides.depth[i], hit.t, 1e-4f * hit.t);
      EXPECT_NEAR(glm::length(guides.normal[i]), 1.0f, 1e-5f);
      EXPECT_LT(glm::dot(guides.normal[i], rays.ray(x, y).direction), 0.0f) << "facing the eye";
      EXPECT_NEAR(glm::distance(guides.albedo[i], vec3(0.6f, 0.7f, 0.8f)), 0.0f, 1e-6f);
    }
  EXPECT_GT(hits, 50);
  EXPECT_GT(misses, 50);
}

/// Mean over pixels of the squared difference (red channel: the scene is grey).
double mse(const Framebuffer& a, const Framebuffer& b) {
  double sum = 0.0;
  for (std::size_t i = 0; i < a.pixel_count(); ++i) {
    const double d = double(a.pixels()[i].x) - double(b.pixels()[i].x);
    sum += d * d;
  }
  return sum / double(a.pixel_count());
}

Framebuffer render_penumbra(std::uint32_t samples, std::uint32_t seed) {
  ecs::Registry reg;
  penumbra_scene(reg, 4.0f); // the view filled by the penumbra
  return render(reg, shadow_settings(samples, seed), {33, 33});
}

TEST(Shadow, StratifiedSamplesBeatIndependentOnes) {
  const Framebuffer reference = render_penumbra(2048, 99);
  // Independent samples: one sample of a scrambled net is uniformly distributed, and pixels and
  // seeds are scrambled independently, so 1-sample renders under K seeds are K independent
  // uniform samples per pixel; their mean squared error / N is independent sampling's at N.
  constexpr int kSeeds = 16;
  double single = 0.0;
  for (int k = 0; k < kSeeds; ++k) single += mse(render_penumbra(1, 1000 + k), reference);
  single /= kSeeds;
  std::vector<double> errors;
  for (const std::uint32_t n : {4u, 16u, 64u}) {
    double e = 0.0;
    for (std::uint32_t seed = 1; seed <= 4; ++seed) e += mse(render_penumbra(n, seed), reference);
    errors.push_back(e / 4.0);
  }
  std::printf("independent 1: %g, 16: %g; stratified 4: %g, 16: %g, 64: %g\n", single,
              single / 16.0, errors[0], errors[1], errors[2]);
  EXPECT_LT(errors[1], 0.5 * single / 16.0);
  // Least-squares slope of log error against log N over 4, 16, 64.
  const double slope = (std::log(errors[2]) - std::log(errors[0])) / std::log(16.0);
  EXPECT_LT(slope, -1.0);
}

/// Surfaces anywhere around the emitters of `table` — in front of and behind the lights and
/// themselves, on a light's plane (cos 0 at the light), on its corner (distance 0), and far
/// enough for the distance to overflow — whose vectorised light samples must be the scalar ones
/// bit for bit.
void expect_vectorised_light_samples_equal_scalar_ones(const EmitterTable& table) {
  std::mt19937 rng(41);
  std::uniform_real_distribution<float> coordinate(-4.0f, 4.0f), unit(0.0f, 1.0f);
  std::normal_distribution<float> gauss;
  const auto direction = [&] { return glm::normalize(vec3(gauss(rng), gauss(rng), gauss(rng))); };
  detail::ShadowSurfaces surfaces;
  constexpr std::size_t kSurfaces = 8 * 125 + 5; // a tail past the last group of eight
  for (std::size_t n = 0; n < kSurfaces; ++n) {
    vec3 origin(coordinate(rng), coordinate(rng), coordinate(rng));
    const EmitterTriangle& e = table.triangles()[n % table.triangles().size()];
    if (n % 11 == 0) origin = e.p0 + unit(rng) * 0.5f * e.e1 + unit(rng) * 0.5f * e.e2;
    if (n % 13 == 0) origin = e.p0;
    if (n % 17 == 0) origin = vec3(3e19f, -2e19f, 1e19f);
    const vec3 normal = direction();
    // The shading normal tilted off the geometric one, sometimes past the horizon.
    const vec3 shading = glm::normalize(normal + 0.8f * direction());
    surfaces.push(origin, normal, shading, vec3(unit(rng), unit(rng), unit(rng)),
                  std::uint32_t(n * 7), PixelSampler(std::uint32_t(n * 7), 3).stream2(0));
  }
  detail::ShadowLightRays vector, scalar;
  std::size_t valid = 0;
  for (const std::uint32_t index : {0u, 1u, 2u, 3u, 17u, 255u, 4096u, 0xFFFFFFF0u}) {
    detail::shadow_light_rays(table, surfaces, index, 0.25f, vector, true);
    detail::shadow_light_rays(table, surfaces, index, 0.25f, scalar, false);
    for (std::size_t n = 0; n < kSurfaces; ++n) {
      ASSERT_EQ(vector.valid[n], scalar.valid[n]) << "surface " << n << " sample " << index;
      if (scalar.valid[n] == 0) continue;
      ++valid;
      const float a[7] = {vector.dx[n], vector.dy[n], vector.dz[n], vector.tfar[n],
                          vector.vr[n], vector.vg[n], vector.vb[n]};
      const float b[7] = {scalar.dx[n], scalar.dy[n], scalar.dz[n], scalar.tfar[n],
                          scalar.vr[n], scalar.vg[n], scalar.vb[n]};
      ASSERT_EQ(std::memcmp(a, b, sizeof(a)), 0) << "surface " << n << " sample " << index;
    }
  }
  // Both kinds occur: the comparison covers lit samples and each early exit.
  EXPECT_GT(valid, 8 * kSurfaces / 5);
  EXPECT_LT(valid, 8 * kSurfaces * 4 / 5);
}

/// Emitters of unequal power and orientation: the first `planes` of five quads (two triangles
/// each, or with `solids` 512), then (with `solids`) a box and a sphere.
void emitters(ecs::Registry& reg, int planes, bool solids) {
  const auto emitter = [&](const MeshSource& mesh, const vec3& at, const quat& rotation,
                           const vec3& emission) {
    Material m;
    m.base_color = vec3(0.0f);
    m.emission = emission;
    test::add_mesh(reg, mesh, test::at(at, vec3(1.0f), rotation), m);
  };
  const struct {
    float size;
    vec3 at;
    quat rotation;
    vec3 emission;
  } quads[] = {
      {0.7f, vec3(0, 2, 0), quat(0, 1, 0, 0), vec3(4, 3, 2)},
      {0.3f, vec3(1.5f, 1, -1), glm::angleAxis(0.7f, glm::normalize(vec3(1, 0, 1))), vec3(1)},
      {2.0f, vec3(3, 3, 3), glm::angleAxis(2.5f, glm::normalize(vec3(1, 1, 0))), vec3(0.1f)},
      {0.5f, vec3(-1, 2.5f, 1), glm::angleAxis(1.2f, glm::normalize(vec3(0, 1, 1))), vec3(9, 1, 1)},
      {1.0f, vec3(0.5f, -2, -1), glm::angleAxis(0.3f, vec3(1, 0, 0)), vec3(0.5f, 0.5f, 3)}};
  for (int q = 0; q < planes; ++q)
    emitter(test::primitive("plane", 1.0f, vec3(quads[q].size), 32, solids ? 16 : 1), quads[q].at,
            quads[q].rotation, quads[q].emission);
  if (!solids) return;
  emitter(test::primitive("box", 1.0f, vec3(0.4f, 0.2f, 0.6f)), vec3(-2, 0.5f, 0.3f),
          glm::angleAxis(1.9f, vec3(0, 0, 1)), vec3(0.5f, 2, 1));
  emitter(test::primitive("sphere", 0.3f, vec3(1.0f), 8, 8), vec3(0.2f, -1.5f, 2), quat(1, 0, 0, 0),
          vec3(7, 7, 7));
}

TEST(Shadow, VectorisedLightSamplesEqualTheScalarOnesBitForBit) {
  if (!detail::shadow_light_rays_vectorised()) GTEST_SKIP() << "this CPU has no AVX2";
  ecs::Registry reg;
  emitters(reg, 5, true);
  const test::TracedWorld w(reg);
  ASSERT_GE(w.layer.emitters().triangles().size(), 1024u); // the pick's search runs 10 steps
  expect_vectorised_light_samples_equal_scalar_ones(w.layer.emitters());
}

TEST(Shadow, VectorisedLightSamplesFromSmallTablesEqualTheScalarOnes) {
  // Tables of up to eight triangles are held in registers (a permute per field, the pick a
  // count of cdfs): 2, 6 and 8 triangles.
  if (!detail::shadow_light_rays_vectorised()) GTEST_SKIP() << "this CPU has no AVX2";
  for (const int planes : {1, 3, 4}) {
    ecs::Registry reg;
    emitters(reg, planes, false);
    const test::TracedWorld w(reg);
    ASSERT_EQ(w.layer.emitters().triangles().size(), std::size_t(2 * planes));
    SCOPED_TRACE(testing::Message() << planes << " quads");
    expect_vectorised_light_samples_equal_scalar_ones(w.layer.emitters());
  }
}

} // namespace
} // namespace specula
