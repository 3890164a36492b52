// Properties of the path tracer (trace/path_integrator.cpp): furnace scenes give their analytic
// radiance within a statistical bound, independent seeds converge to a reference at the Monte
// Carlo rate, the three light-sampling strategies agree, MIS weights sum to 1, images do not
// depend on threads, tiles or packets, and a scene with point lights only matches Whitted.

#include "scene_builder.h"
#include "specula/trace/area_lights.h"
#include "specula/trace/render_frame.h"
#include "specula/trace/sampler.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

namespace specula {
namespace {

/// A mesh without vertex normals: shaded flat, so that shading and geometric normals agree and a
/// furnace loses no energy to directions below the geometric surface.
ecs::Entity add_flat_mesh(ecs::Registry& reg, TriangleMesh mesh, const Transform& t,
                          const Material& m) {
  mesh.normals.clear();
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e, t);
  reg.emplace<Mesh>(e, Mesh{std::make_shared<const TriangleMesh>(std::move(mesh)), {}, {}, 0});
  reg.emplace<Material>(e, m);
  reg.emplace<Kinematics>(e, Kinematics{Kinematics::Type::Static});
  return e;
}

Material diffuse(const vec3& base_color, const vec3& emission = vec3(0.0f)) {
  Material m;
  m.base_color = base_color;
  m.emission = emission;
  return m;
}

Camera camera_at(const vec3& position, const vec3& look_at, float fov_degrees) {
  Camera c;
  c.position = dvec3(position);
  c.look_at = dvec3(look_at);
  c.vertical_fov = glm::radians(fov_degrees);
  return c;
}

TraceSettings path_settings(std::uint32_t spp, std::uint32_t seed,
                            LightSampling sampling = LightSampling::Mis,
                            std::uint32_t max_depth = 5) {
  TraceSettings s;
  s.mode = TraceMode::Path;
  s.spp = spp;
  s.seed = seed;
  s.sampling = sampling;
  s.max_depth = max_depth;
  s.threads = 2;
  return s;
}

Framebuffer render(const test::TracedWorld& world, const Camera& camera,
                   const TraceSettings& settings, std::uint32_t width, std::uint32_t height,
                   GuideBuffers* guides = nullptr) {
  Framebuffer image(width, height);
  render_frame(*world.tracer, world.layer, camera, settings, image, nullptr, guides);
  return image;
}

/// Per pixel and channel: the mean of independent frames and the standard error of that mean.
struct Estimate {
  std::vector<vec3> mean, error;
};

/// `frames` frames with seeds first_seed, first_seed + 1, …: independent estimates of the image.
Estimate estimate(const test::TracedWorld& world, const Camera& camera, TraceSettings settings,
                  std::uint32_t width, std::uint32_t height, std::uint32_t frames,
                  std::uint32_t first_seed) {
  const std::size_t n = std::size_t(width) * height;
  std::vector<dvec3> sum(n, dvec3(0.0)), sum2(n, dvec3(0.0));
  for (std::uint32_t f = 0; f < frames; ++f) {
    settings.seed = first_seed + f;
    const Framebuffer image = render(world, camera, settings, width, height);
    for (std::size_t i = 0; i < n; ++i) {
      const dvec3 v(image.pixels()[i]);
      sum[i] += v;
      sum2[i] += v * v;
    }
  }
  Estimate e;
  for (std::size_t i = 0; i < n; ++i) {
    const dvec3 mean = sum[i] / double(frames);
    const dvec3 variance = glm::max(sum2[i] / double(frames) - mean * mean, dvec3(0.0)) *
                           (double(frames) / (frames - 1));
    e.mean.push_back(vec3(mean));
    e.error.push_back(vec3(glm::sqrt(variance / double(frames))));
  }
  return e;
}

/// A sphere of radius 1 (flat icosphere) inside an inward-seen sphere of radius 10, both given
/// materials; the camera inside the enclosure looks at the sphere, which fills part of the image.
struct Furnace {
  ecs::Registry reg;
  std::unique_ptr<test::TracedWorld> world;
  Camera camera = camera_at(vec3(0.0f, 0.5f, 4.0f), vec3(0.0f), 45.0f);

  Furnace(const Material& sphere, const Material& enclosure) {
    add_flat_mesh(reg, test::icosphere(3), test::at(vec3(0.0f)), sphere);
    add_flat_mesh(reg, test::icosphere(2), test::at(vec3(0.0f), vec3(10.0f)), enclosure);
    world = std::make_unique<test::TracedWorld>(reg);
  }
};

/// Every pixel's estimate lies within 5 standard errors of `expected` (plus float rounding). A
/// furnace's pixels all estimate one value with similar variance, so the error is the larger of
/// the pixel's own and the image's root-mean-square one: a pixel that by chance drew none of the
/// rare long paths Russian roulette lets through also underestimates its own variance.
void expect_all_pixels(const Estimate& e, const vec3& expected, const char* what) {
  dvec3 pooled(0.0);
  for (const vec3& error : e.error) pooled += dvec3(error) * dvec3(error);
  pooled = glm::sqrt(pooled / double(e.error.size()));
  int outside = 0;
  for (std::size_t i = 0; i < e.mean.size(); ++i)
    for (int c = 0; c < 3; ++c) {
      const float bound = 5.0f * std::max(e.error[i][c], float(pooled[c])) + 1e-5f * expected[c];
      if (std::abs(e.mean[i][c] - expected[c]) > bound) {
        if (++outside <= 3)
          ADD_FAILURE() << what << ": pixel " << i << " channel " << c << " = " << e.mean[i][c]
                        << " ± " << e.error[i][c] << ", expected " << expected[c];
      }
    }
  EXPECT_EQ(outside, 0) << what;
}

const LightSampling kSamplings[] = {LightSampling::Mis, LightSampling::Bsdf, LightSampling::Light};

TEST(PathFurnace, AWhiteSphereInAUniformlyEmittingEnclosureReflectsTheEmission) {
  const vec3 emission(0.5f, 1.0f, 2.0f);
  Furnace furnace(diffuse(vec3(1.0f)), diffuse(vec3(0.0f), emission));
  for (const LightSampling sampling : kSamplings) {
    const Estimate e =
        estimate(*furnace.world, furnace.camera, path_settings(4, 0, sampling), 32, 24, 16, 100);
    expect_all_pixels(e, emission, light_sampling_name(sampling));
  }
}

TEST(PathFurnace, HalfAlbedoEverywhereGivesTheTruncatedGeometricSeries) {
  // Every surface emits E with albedo a: radiance is uniform, E·Σ a^k over the vertices a path
  // may have (the primary hit and max_depth bounces), Russian roulette included (unbiased).
  const vec3 emission(0.25f, 0.5f, 1.0f);
  const float a = 0.5f;
  const std::uint32_t max_depth = 8;
  Furnace furnace(diffuse(vec3(a), emission), diffuse(vec3(a), emission));
  const float series = (1.0f - std::pow(a, float(max_depth + 1))) / (1.0f - a);
  for (const LightSampling sampling : kSamplings) {
    const Estimate e = estimate(*furnace.world, furnace.camera,
                                path_settings(16, 0, sampling, max_depth), 24, 18, 16, 200);
    expect_all_pixels(e, emission * series, light_sampling_name(sampling));
  }
}

/// A small closed Cornell-like box: diffuse walls, an emissive panel under the ceiling, a diffuse
/// block, a mirror sphere and a glass sphere, and (optionally) a point light. The panel is large
/// (a third of the ceiling's width and more), so that BSDF sampling finds it often and both MIS
/// weights matter: with a small panel a wrong MIS weight hides in the noise.
struct SmallCornell {
  ecs::Registry reg;
  std::unique_ptr<test::TracedWorld> world;
  // Off the box's symmetry: a camera ray exactly along a box edge may hit either face, and the
  // backends' packet and single-ray kernels break such ties differently.
  Camera camera = camera_at(vec3(0.0131f, 0.0217f, 1.7f), vec3(0.031f, -0.019f, -1.0f), 70.0f);

  explicit SmallCornell(bool point_light = true, std::uint32_t packet_width = 16) {
    test::add_mesh(reg, test::primitive("box", 1.0f, vec3(4.0f)), test::at(vec3(0.0f)),
                   diffuse(vec3(0.7f, 0.6f, 0.5f)));
    test::add_mesh(reg, test::primitive("plane", 1.0f, vec3(2.5f)),
                   test::at(vec3(0.0f, 1.9f, 0.0f)), diffuse(vec3(0.0f), vec3(1.5f, 1.25f, 1.0f)));
    test::add_mesh(reg, test::primitive("box", 1.0f, vec3(1.0f, 1.6f, 1.0f)),
                   test::at(vec3(-1.0f, -1.2f, -1.0f)), diffuse(vec3(0.3f, 0.6f, 0.3f)));
    Material mirror;
    mirror.base_color = vec3(0.9f);
    mirror.reflectivity = 0.8f;
    test::add_mesh(reg, test::primitive("sphere", 0.5f, vec3(1.0f), 24, 12),
                   test::at(vec3(0.9f, -1.5f, -0.8f)), mirror);
    Material glass;
    glass.base_color = vec3(1.0f);
    glass.reflectivity = 0.05f;
    glass.transmission = 0.9f;
    test::add_mesh(reg, test::primitive("sphere", 0.5f, vec3(1.0f), 24, 12),
                   test::at(vec3(0.3f, -0.3f, -0.2f)), glass);
    if (point_light) test::add_point_light(reg, vec3(0.5f, 1.5f, 0.5f), 2.0f);
    world = std::make_unique<test::TracedWorld>(reg, "auto", packet_width);
  }
};

double rmse(const std::vector<vec3>& image, const std::vector<vec3>& reference) {
  double sum = 0.0;
  for (std::size_t i = 0; i < reference.size(); ++i) {
    const vec3 d = image[i] - reference[i];
    sum += glm::dot(dvec3(d), dvec3(d));
  }
  return std::sqrt(sum / (3.0 * double(reference.size())));
}

TEST(PathUnbiased, TheMeanOfIndependentSeedsConvergesLikeOneOverRootK) {
  SmallCornell scene(false);
  constexpr std::uint32_t w = 24, h = 18;
  // The reference: a high-sample render with a seed none of the estimates uses.
  const Framebuffer reference_image =
      render(*scene.world, scene.camera, path_settings(1024, 999999), w, h);
  const std::vector<vec3> reference(reference_image.pixels().begin(),
                                    reference_image.pixels().end());
  // Mean of K one-sample frames, averaged over a few disjoint groups of seeds to steady the fit.
  const std::uint32_t ks[] = {1, 2, 4, 8, 16, 32};
  constexpr int kGroups = 3;
  std::vector<double> log_k, log_error;
  std::uint32_t seed = 1;
  for (const std::uint32_t k : ks) {
    double error = 0.0;
    for (int g = 0; g < kGroups; ++g) {
      std::vector<vec3> mean(reference.size(), vec3(0.0f));
      for (std::uint32_t f = 0; f < k; ++f) {
        const Framebuffer frame =
            render(*scene.world, scene.camera, path_settings(1, seed++), w, h);
        for (std::size_t i = 0; i < mean.size(); ++i) mean[i] += frame.pixels()[i] / float(k);
      }
      error += rmse(mean, reference) / kGroups;
    }
    log_k.push_back(std::log(double(k)));
    log_error.push_back(std::log(error));
  }
  // Least-squares slope of log error against log K.
  const double n = double(log_k.size());
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (std::size_t i = 0; i < log_k.size(); ++i) {
    sx += log_k[i];
    sy += log_error[i];
    sxx += log_k[i] * log_k[i];
    sxy += log_k[i] * log_error[i];
  }
  const double slope = (n * sxy - sx * sy) / (n * sxx - sx * sx);
  EXPECT_GE(slope, -0.7);
  EXPECT_LE(slope, -0.3);
}

TEST(PathUnbiased, MisBsdfAndLightSamplingAgreeOnACornellBox) {
  SmallCornell scene;
  constexpr std::uint32_t w = 16, h = 12, frames = 24;
  std::vector<dvec3> mean, error;
  for (const LightSampling sampling : kSamplings) {
    const Estimate e =
        estimate(*scene.world, scene.camera, path_settings(16, 0, sampling), w, h, frames, 7);
    // The image mean and its standard error (pixels are independent).
    dvec3 m(0.0), v(0.0);
    for (std::size_t i = 0; i < e.mean.size(); ++i) {
      m += dvec3(e.mean[i]);
      v += dvec3(e.error[i]) * dvec3(e.error[i]);
    }
    const double n = double(e.mean.size());
    mean.push_back(m / n);
    error.push_back(glm::sqrt(v) / n);
  }
  for (std::size_t a = 0; a < 3; ++a)
    for (std::size_t b = a + 1; b < 3; ++b)
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(mean[a][c], mean[b][c],
                    5.0 * std::sqrt(error[a][c] * error[a][c] + error[b][c] * error[b][c]))
            << light_sampling_name(kSamplings[a]) << " vs " << light_sampling_name(kSamplings[b])
            << ", channel " << c;
}

TEST(PathMis, PowerHeuristicWeightsSumToOneForEverySampledPair) {
  // Densities the integrator pairs: light samples of the box's panel from points in the box
  // (their area-light pdf against the diffuse pdf of the same direction), and cosine-sampled
  // directions (diffuse pdf against the panel's pdf where they hit it), plus extremes.
  SmallCornell scene(false);
  const EmitterTable& table = scene.world->layer.emitters();
  ASSERT_FALSE(table.empty());
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<std::pair<float, float>> pairs;
  for (int i = 0; i < 2000; ++i) {
    const vec3 p(4.0f * u(rng) - 2.0f, 4.0f * u(rng) - 2.0f, 4.0f * u(rng) - 2.0f);
    const vec3 n = glm::normalize(vec3(u(rng) - 0.5f, u(rng) - 0.5f, u(rng) - 0.5f));
    const AreaLightSample ls = sample_area_light(table, p, u(rng), u(rng), u(rng));
    const float cos_theta = glm::dot(ls.to_light, n);
    pairs.emplace_back(ls.pdf, std::max(0.0f, cos_theta) * std::numbers::inv_pi_v<float>);
    // A light point's density from a point where a BSDF ray could have left.
    const EmitterTriangle& e = table.triangles()[ls.triangle];
    pairs.emplace_back(u(rng) * std::numbers::inv_pi_v<float>, area_light_pdf(e, p, ls.position));
  }
  const float inf = std::numeric_limits<float>::infinity();
  const float extremes[] = {0.0f,   inf,   1e-30f, 1e-45f, std::numeric_limits<float>::min(),
                            1e-20f, 1e20f, 1e30f,  3e38f,  std::numeric_limits<float>::max(),
                            1.0f,   0.5f};
  for (const float a : extremes)
    for (const float b : extremes) pairs.emplace_back(a, b);
  for (const auto& [a, b] : pairs) {
    const float wa = power_heuristic(a, b), wb = power_heuristic(b, a);
    EXPECT_GE(wa, 0.0f);
    EXPECT_LE(wa, 1.0f);
    EXPECT_NEAR(wa + wb, 1.0f, 1e-6f) << "pdfs " << a << " and " << b;
  }
}

TEST(PathDeterminism, ImagesAreIdenticalWhateverTheThreadsTilesAndPacketWidth) {
  struct Variant {
    std::uint32_t threads, tile, packet;
  };
  const Variant variants[] = {{1, 16, 16}, {2, 8, 4}, {2, 32, 1}, {2, 16, 8}};
  std::vector<Framebuffer> images;
  std::vector<GuideBuffers> guides(std::size(variants));
  for (std::size_t v = 0; v < std::size(variants); ++v) {
    SmallCornell scene(true, variants[v].packet);
    TraceSettings s = path_settings(16, 3);
    s.threads = variants[v].threads;
    s.tile_size = variants[v].tile;
    // 32×32 tiles × 16 spp exceed one batch of paths: batches must not change the sums either.
    images.push_back(render(*scene.world, scene.camera, s, 40, 30, &guides[v]));
  }
  for (std::size_t v = 1; v < images.size(); ++v) {
    for (std::size_t i = 0; i < images[0].pixel_count(); ++i) {
      ASSERT_EQ(images[v].pixels()[i], images[0].pixels()[i]) << "variant " << v << " pixel " << i;
      ASSERT_EQ(guides[v].albedo[i], guides[0].albedo[i]);
      ASSERT_EQ(guides[v].normal[i], guides[0].normal[i]);
      ASSERT_EQ(guides[v].depth[i], guides[0].depth[i]);
    }
  }
}

TEST(PathDeterminism, SeedsAndSampleOffsetsChangeTheImage) {
  SmallCornell scene;
  TraceSettings s = path_settings(1, 0);
  const Framebuffer a = render(*scene.world, scene.camera, s, 16, 12);
  s.seed = 1;
  const Framebuffer b = render(*scene.world, scene.camera, s, 16, 12);
  s.seed = 0;
  s.sample_offset = 1;
  const Framebuffer c = render(*scene.world, scene.camera, s, 16, 12);
  const auto differ = [](const Framebuffer& x, const Framebuffer& y) {
    for (std::size_t i = 0; i < x.pixel_count(); ++i)
      if (x.pixels()[i] != y.pixels()[i]) return true;
    return false;
  };
  EXPECT_TRUE(differ(a, b));
  EXPECT_TRUE(differ(a, c));
}

TEST(PathGuides, AlbedoNormalAndDepthOfThePrimaryHits) {
  ecs::Registry reg;
  Material half_mirror = diffuse(vec3(0.2f, 0.4f, 0.6f));
  half_mirror.reflectivity = 0.5f;
  test::add_mesh(reg, test::primitive("plane", 1.0f, vec3(2.0f)), test::at(vec3(0.0f)),
                 half_mirror);
  test::TracedWorld world(reg);
  // Looking straight down at the plane's centre; the corners of a wide view miss it.
  Camera camera = camera_at(vec3(0.0f, 2.0f, 0.0f), vec3(0.0f), 90.0f);
  camera.up = vec3(0.0f, 0.0f, -1.0f);
  GuideBuffers guides;
  (void)render(world, camera, path_settings(1, 0), 8, 8, &guides);
  ASSERT_EQ(guides.size(), 64u);
  // The centre pixels see the plane at distance ≈ 2.
  const std::size_t centre = 4 * 8 + 4;
  EXPECT_NEAR(guides.depth[centre], 2.0f, 0.1f);
  EXPECT_NEAR(guides.normal[centre].y, 1.0f, 1e-5f);
  const vec3 albedo = 0.5f * vec3(0.2f, 0.4f, 0.6f) + vec3(0.5f);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(guides.albedo[centre][c], albedo[c], 1e-6f);
  // The corner sees past the 2×2 plane: a miss.
  EXPECT_TRUE(std::isinf(guides.depth[0]));
  EXPECT_EQ(guides.normal[0], vec3(0.0f));
  EXPECT_EQ(guides.albedo[0], vec3(1.0f));
}

TEST(PathPointLights, ASceneWithPointLightsOnlyMatchesWhittedAtDepthZero) {
  // Diffuse surfaces and one point light, no emitters and no specular materials: the path
  // tracer's primary hit with next-event estimation is Whitted's local shading.
  ecs::Registry reg;
  test::add_mesh(reg, test::primitive("plane", 1.0f, vec3(10.0f)), test::at(vec3(0.0f)),
                 diffuse(vec3(0.7f, 0.6f, 0.5f)));
  test::add_mesh(reg, test::primitive("sphere", 0.6f, vec3(1.0f), 32, 16),
                 test::at(vec3(0.0f, 0.7f, 0.0f)), diffuse(vec3(0.2f, 0.5f, 0.8f)));
  test::add_mesh(reg, test::primitive("box", 1.0f, vec3(0.6f)), test::at(vec3(-1.2f, 0.3f, 0.4f)),
                 diffuse(vec3(0.9f, 0.3f, 0.2f)));
  test::add_point_light(reg, vec3(1.0f, 3.0f, 1.5f), 20.0f);
  test::TracedWorld world(reg);
  ASSERT_FALSE(world.layer.emitters().features().area_lights);
  const Camera camera = camera_at(vec3(0.5f, 2.0f, 5.0f), vec3(0.0f, 0.3f, 0.0f), 50.0f);
  for (const LightSampling sampling : kSamplings) {
    TraceSettings path = path_settings(1, 5, sampling, 0);
    path.background = vec3(0.1f, 0.2f, 0.3f);
    TraceSettings whitted = path;
    whitted.mode = TraceMode::Whitted;
    const Framebuffer a = render(world, camera, path, 48, 36);
    const Framebuffer b = render(world, camera, whitted, 48, 36);
    for (std::size_t i = 0; i < a.pixel_count(); ++i)
      ASSERT_EQ(a.pixels()[i], b.pixels()[i]) << light_sampling_name(sampling) << " pixel " << i;
  }
}

TEST(PathPointLights, ManyLightsShadeAsTheWavesBatchedSamplesDo) {
  // A wave samples up to eight point lights ahead for all its vertices at once (vertex_starts.h);
  // with more, each vertex samples them as it shades. A ninth light of zero intensity adds
  // nothing, so the two ways must give the same image, bit for bit, here with bounces, an area
  // light and a mirror.
  const auto scene = [](ecs::Registry& reg, bool ninth) {
    test::add_mesh(reg, test::primitive("plane", 1.0f, vec3(10.0f)), test::at(vec3(0.0f)),
                   diffuse(vec3(0.7f, 0.6f, 0.5f)));
    Material mirror = diffuse(vec3(0.9f));
    mirror.reflectivity = 0.6f;
    test::add_mesh(reg, test::primitive("sphere", 0.6f, vec3(1.0f), 32, 16),
                   test::at(vec3(0.0f, 0.7f, 0.0f)), mirror);
    test::add_mesh(reg, test::primitive("plane", 1.0f, vec3(0.8f)),
                   test::at(vec3(0.0f, 3.0f, 0.0f), vec3(1.0f), quat(0, 1, 0, 0)),
                   diffuse(vec3(0.0f), vec3(3.0f, 2.5f, 2.0f)));
    for (int l = 0; l < 8; ++l) {
      const float a = 0.785f * float(l);
      test::add_point_light(reg,
                            vec3(2.5f * std::cos(a), 1.0f + 0.3f * float(l), 2.5f * std::sin(a)),
                            2.0f + float(l));
    }
    if (ninth) test::add_point_light(reg, vec3(0.5f, 2.0f, -1.0f), 0.0f);
  };
  ecs::Registry few_reg, many_reg;
  scene(few_reg, false);
  scene(many_reg, true);
  test::TracedWorld few(few_reg), many(many_reg);
  ASSERT_EQ(few.layer.tables().lights.size(), 8u);
  ASSERT_EQ(many.layer.tables().lights.size(), 9u);
  const Camera camera = camera_at(vec3(0.5f, 2.0f, 5.0f), vec3(0.0f, 0.5f, 0.0f), 50.0f);
  const TraceSettings settings = path_settings(2, 7, LightSampling::Mis, 4);
  const Framebuffer a = render(few, camera, settings, 48, 36);
  const Framebuffer b = render(many, camera, settings, 48, 36);
  std::size_t lit = 0;
  for (std::size_t i = 0; i < a.pixel_count(); ++i) {
    ASSERT_EQ(a.pixels()[i], b.pixels()[i]) << "pixel " << i;
    const vec3 c = a.pixels()[i];
    lit += std::max(c.x, std::max(c.y, c.z)) > 0.0f;
  }
  EXPECT_GT(lit, a.pixel_count() / 2);
}

TEST(PathCounts, RaysAreCountedByKind) {
  SmallCornell scene;
  Framebuffer image(16, 12);
  const FrameStats stats = render_frame(*scene.world->tracer, scene.world->layer, scene.camera,
                                        path_settings(2, 0), image);
  // Primaries once per pixel however many samples; the rest by what the paths did.
  EXPECT_EQ(stats.rays[RayKind::Primary], 16u * 12u);
  EXPECT_GT(stats.rays[RayKind::Shadow], 0u);
  EXPECT_GT(stats.rays[RayKind::Reflection], 0u);
  EXPECT_GT(stats.rays[RayKind::Refraction], 0u);
  EXPECT_EQ(stats.rays.nonfinite, 0u);
}

} // namespace
} // namespace specula
