// Ray-cache cubes through the schedule: what lookups return, what invalidation outdates when
// entities move, what the auto policy decides, and that frames stay deterministic.

#include "../trace/scene_builder.h"
#include "specula/cache/cube_map.h"
#include "specula/cache/ray_cache.h"
#include "specula/image/metrics.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <limits>
#include <map>
#include <mutex>
#include <numbers>
#include <tuple>

namespace specula {
namespace {

using cache::CachePolicy;
using cache::CacheSettings;
using cache::LookupMode;
using cache::RayCacheStore;

cache::RayCacheStore& store_of(ecs::Registry& reg) { return *reg.resource<cache::RayCaches>().store; }

Material mirror_material(float reflectivity = 0.9f) {
  Material m;
  m.base_color = vec3(0.9f);
  m.reflectivity = reflectivity;
  return m;
}

Material emissive(const vec3& c) {
  Material m;
  m.base_color = vec3(0.0f);
  m.emission = c;
  return m;
}

Material diffuse(const vec3& c) {
  Material m;
  m.base_color = c;
  return m;
}

/// A world: a mirror sphere of radius 1 at the origin with a cube of `resolution`, the camera at
/// `eye` looking at it, and whatever `build` adds; rendering prepared with `cache`.
struct World {
  ecs::Registry reg;
  Schedule schedule;
  ecs::Entity mirror;
  ecs::Entity camera;
};

template <typename Build>
void make_world(World& w, const CacheSettings& cache, std::uint32_t resolution, Build build,
                std::uint32_t size = 96, vec3 eye = vec3(0.0f, 0.3f, 4.0f), std::uint32_t threads = 2,
                const Material& mirror = mirror_material()) {
  w.mirror = test::add_mesh(w.reg, test::primitive("sphere", 1.0f, vec3(1.0f), 48, 24), test::at(vec3(0.0f)),
                            mirror, Kinematics::Type::Free);
  w.reg.emplace<RayCacheCube>(w.mirror, RayCacheCube{resolution});
  w.camera = test::add_camera(w.reg, eye, vec3(0.0f), 40.0f);
  build(w.reg);
  RenderJob job;
  job.settings.mode = TraceMode::Whitted;
  job.settings.max_depth = 4;
  job.settings.background = vec3(0.1f, 0.15f, 0.3f);
  job.settings.threads = threads;
  job.image = Framebuffer(size, size);
  job.cache = cache;
  prepare_rendering(w.reg, std::move(job));
}

Framebuffer frame(World& w) {
  w.schedule.tick(w.reg, 1.0 / 60.0);
  return w.reg.resource<RenderJob>().image;
}

CacheSettings on(LookupMode mode, bool prefill = false) {
  CacheSettings s;
  s.policy = CachePolicy::On;
  s.lookup = mode;
  s.prefill = prefill;
  return s;
}

void move(ecs::Registry& reg, ecs::Entity e, const vec3& to) {
  reg.patch<Transform>(e, [&](Transform& t) { t.translation = to; });
}

void orbit(World& w, float degrees) {
  w.reg.patch<Camera>(w.camera, [&](Camera& c) {
    const float a = glm::radians(degrees);
    const vec3 p = c.position;
    c.position = vec3(std::cos(a) * p.x + std::sin(a) * p.z, p.y, -std::sin(a) * p.x + std::cos(a) * p.z);
  });
}

// ---------------------------------------------------------------------------------------------

/// Far away (2000 radii) emissive spheres and a diffuse ground far below, all around.
void distant_surroundings(ecs::Registry& reg) {
  const vec3 colours[] = {vec3(0.9f, 0.2f, 0.1f), vec3(0.1f, 0.8f, 0.3f), vec3(0.2f, 0.3f, 0.9f),
                          vec3(0.9f, 0.9f, 0.2f), vec3(0.8f, 0.2f, 0.8f), vec3(0.2f, 0.9f, 0.9f)};
  const vec3 where[] = {vec3(2000, 300, 0),  vec3(-2000, 0, 500), vec3(0, 600, 2000),
                        vec3(300, -200, -2000), vec3(1400, 900, 1400), vec3(-1400, -300, -1400)};
  for (int i = 0; i < 6; ++i)
    test::add_mesh(reg, test::primitive("sphere", 300.0f), test::at(where[i]), emissive(colours[i]));
}

TEST(RayCache, SurroundingsAtInfinityCachedEqualsUncached) {
  // Direction-only caching is exact for content at infinity: fill while the camera orbits, then
  // look from a new place: every lookup answers with what another shading point stored.
  World cached, reference;
  make_world(cached, on(LookupMode::Direction), 128, distant_surroundings);
  make_world(reference, CacheSettings{}, 128, distant_surroundings);
  for (int k = 0; k < 6; ++k) {
    (void)frame(cached);
    orbit(cached, 1.0f);
    orbit(reference, 1.0f);
  }
  const Framebuffer a = frame(cached);
  const Framebuffer b = frame(reference);
  const CacheCounts& c = store_of(cached.reg).counts();
  ASSERT_GT(c.hits, c.lookups / 4) << "a good part of the leaving rays must be served";
  EXPECT_GE(psnr(a, b), 45.0);
}

TEST(RayCache, ServedRaysAreNotTraced) {
  World w;
  make_world(w, on(LookupMode::Direction), 128, distant_surroundings);
  (void)frame(w);
  const FrameStats first = w.reg.resource<RenderJob>().last;
  (void)frame(w);
  const FrameStats second = w.reg.resource<RenderJob>().last;
  EXPECT_GT(first.rays[RayKind::Reflection], 0u);
  EXPECT_EQ(second.cache.hits, second.cache.lookups) << "static camera: every texel was filled";
  EXPECT_EQ(second.rays[RayKind::Reflection], 0u) << "the only reflective object is cached";
  // Memory: 16 bytes a texel, plus the visibility graph's edge counts (one per entity index).
  EXPECT_GE(second.cache.memory_bytes, 6u * 128u * 128u * 16u);
  EXPECT_LE(second.cache.memory_bytes, 6u * 128u * 128u * 16u + 64u * sizeof(std::uint32_t));
}

TEST(RayCache, GlassCachesItsReflectionAndItsExitingRefraction) {
  Material glass;
  glass.base_color = vec3(1.0f);
  glass.reflectivity = 0.05f;
  glass.transmission = 0.9f;
  glass.ior = 1.5f;
  World w;
  make_world(w, on(LookupMode::Direction), 128, distant_surroundings, 96, vec3(0.0f, 0.3f, 4.0f), 2,
             glass);
  (void)frame(w);
  const FrameStats first = w.reg.resource<RenderJob>().last;
  (void)frame(w);
  const FrameStats second = w.reg.resource<RenderJob>().last;
  ASSERT_GT(second.cache.hits, 0u);
  // Entering refractions and internal reflections stay traced; exiting ones are served.
  EXPECT_LT(second.rays[RayKind::Refraction], first.rays[RayKind::Refraction]);
  EXPECT_GT(second.rays[RayKind::Refraction], 0u);
  EXPECT_LT(second.rays[RayKind::Reflection], first.rays[RayKind::Reflection]);
}

// ---------------------------------------------------------------------------------------------
// Invalidation

/// Two emissive spheres, A at +X and B at −X, 10 away; no lights (no shadows to follow).
struct TwoSpheres {
  ecs::Entity a, b;
  void operator()(ecs::Registry& reg) {
    a = test::add_mesh(reg, test::primitive("sphere", 1.0f), test::at(vec3(10, 0, 0)),
                       emissive(vec3(1, 0, 0)), Kinematics::Type::Free);
    b = test::add_mesh(reg, test::primitive("sphere", 1.0f), test::at(vec3(-10, 0, 0)),
                       emissive(vec3(0, 1, 0)), Kinematics::Type::Free);
  }
};

/// A mirror with a cube of `resolution` between the two spheres, filled from its centre, and a
/// camera that looks away, so frames write nothing: the texels show what invalidation did.
RayCacheStore& prefilled_looking_away(World& w, TwoSpheres& two, std::uint32_t resolution) {
  make_world(
      w, on(LookupMode::Direction), resolution, [&](ecs::Registry& r) { two(r); }, 16,
      vec3(0.0f, 50.0f, 0.0f));
  w.reg.patch<Camera>(w.camera, [](Camera& c) { c.look_at = vec3(0.0f, 100.0f, 1.0f); });
  (void)frame(w);
  RayCacheStore& store = store_of(w.reg);
  EXPECT_EQ(store.cube_count(), 1u);
  store.prefill(*w.reg.resource<ActiveTracer>().tracer, w.reg.resource<SceneLayer>(),
                w.reg.resource<RenderJob>().settings);
  return store;
}

TEST(RayCacheInvalidation, MovingAnEntityOutdatesExactlyTheTexelsThatSawItOrNowCould) {
  TwoSpheres two;
  World w;
  RayCacheStore& store = prefilled_looking_away(w, two, 32);
  ASSERT_EQ(store.cube_count(), 1u);
  const std::vector<cache::Texel> before(store.cube(0).texels.begin(), store.cube(0).texels.end());
  std::uint32_t saw_a = 0, saw_b = 0;
  for (const cache::Texel& t : before) {
    ASSERT_TRUE(t.valid());
    saw_a += t.hit == two.a.index ? 1 : 0;
    saw_b += t.hit == two.b.index ? 1 : 0;
  }
  ASSERT_GT(saw_a, 0u);
  ASSERT_GT(saw_b, 0u);
  // The visibility graph: one edge per entity seen, weighted by texels.
  const auto edges = store.edges(0);
  ASSERT_EQ(edges.size(), 2u);
  for (const auto& [entity, texels] : edges)
    EXPECT_EQ(texels, entity == two.a.index ? saw_a : saw_b);

  const vec3 new_a(0.0f, 0.0f, 10.0f);
  move(w.reg, two.a, new_a);
  (void)frame(w);
  const std::span<const cache::Texel> after = store.cube(0).texels;
  const std::uint32_t res = 32;
  // A's radius plus the mirror's: the directions in which a ray leaving any point of the mirror
  // could meet A.
  const float cone = std::asin((1.0f + 1.0f) / 10.0f);
  const float texel = 2.0f * cache::texel_half_angle(res);
  std::uint64_t outdated = 0;
  for (std::uint32_t i = 0; i < after.size(); ++i) {
    const float angle =
        std::acos(std::min(1.0f, glm::dot(cache::texel_direction(i, res), glm::normalize(new_a))));
    if (before[i].hit == two.a.index || angle <= cone) {
      EXPECT_FALSE(after[i].valid()) << "texel " << i << " saw A or now looks at it";
    }
    if (!after[i].valid()) {
      ++outdated;
      EXPECT_TRUE(before[i].hit == two.a.index || angle <= cone + texel)
          << "texel " << i << " neither saw A nor can see it now";
    } else {
      EXPECT_EQ(std::memcmp(&after[i], &before[i], sizeof(cache::Texel)), 0) << i;
    }
  }
  EXPECT_EQ(store.counts().invalidated, outdated);
  EXPECT_EQ(store.counts().flush_all, before.size());
  // The edge to A is gone; B's is intact.
  for (const auto& [entity, texels] : store.edges(0)) {
    EXPECT_NE(entity, two.a.index);
    EXPECT_EQ(texels, saw_b);
  }
  // Refilled, the cube sees A where it now is.
  store.prefill(*w.reg.resource<ActiveTracer>().tracer, w.reg.resource<SceneLayer>(),
                w.reg.resource<RenderJob>().settings);
  EXPECT_EQ(store.cube(0).texels[cache::texel_of(new_a, res)].hit, two.a.index);
}

// A device copy made at one generation sends only the texels listed since (CubeView::changes):
// the list holds every texel that changed, through invalidation and writes alike; a flush, or
// more changes than the list keeps, leaves no list (changes_from 0: the copy goes up whole).
TEST(RayCacheInvalidation, TheListOfChangesHoldsEveryTexelThatChangedSinceItRestarted) {
  TwoSpheres two;
  World w;
  RayCacheStore& store = prefilled_looking_away(w, two, 64);
  ASSERT_EQ(store.cube_count(), 1u);
  EXPECT_EQ(store.cube(0).changes_from, 0u) << "a whole cube's prefill was listed texel by texel";
  store.restart_journals();
  const std::uint64_t from = store.cube(0).generation;
  EXPECT_EQ(store.cube(0).changes_from, from);
  EXPECT_TRUE(store.cube(0).changes.empty());
  const std::vector<cache::Texel> before(store.cube(0).texels.begin(), store.cube(0).texels.end());
  // A small move of B outdates some texels; a refill writes them again.
  move(w.reg, two.b, vec3(-10.0f, 0.0f, 0.3f));
  (void)frame(w);
  store.prefill(*w.reg.resource<ActiveTracer>().tracer, w.reg.resource<SceneLayer>(),
                w.reg.resource<RenderJob>().settings);
  const cache::CubeView v = store.cube(0);
  ASSERT_NE(v.generation, from) << "nothing changed: no test";
  ASSERT_EQ(v.changes_from, from) << "the list gave up: no test of it";
  std::vector<std::uint8_t> listed(before.size(), 0);
  for (const std::uint32_t i : v.changes) listed.at(i) = 1;
  std::uint32_t differ = 0;
  for (std::size_t i = 0; i < before.size(); ++i)
    if (std::memcmp(&before[i], &v.texels[i], sizeof(cache::Texel)) != 0) {
      ++differ;
      EXPECT_TRUE(listed[i]) << "texel " << i << " changed but is not listed";
    }
  EXPECT_GT(differ, 0u);
  store.flush();
  EXPECT_EQ(store.cube(0).changes_from, 0u);
}

TEST(RayCacheInvalidation, AStoreThatMissedASyncWithChangesOutdatesEveryTexel) {
  // Caching switched off (no store) while A moves: the store back on cannot know what changed in
  // the sync it missed, so nothing it holds may be used.
  TwoSpheres two;
  World w;
  make_world(w, on(LookupMode::Direction), 16, [&](ecs::Registry& r) { two(r); }, 16,
             vec3(0.0f, 50.0f, 0.0f));
  w.reg.patch<Camera>(w.camera, [](Camera& c) { c.look_at = vec3(0.0f, 100.0f, 1.0f); });
  (void)frame(w);
  auto fill = [&] {
    store_of(w.reg).prefill(*w.reg.resource<ActiveTracer>().tracer, w.reg.resource<SceneLayer>(),
                            w.reg.resource<RenderJob>().settings);
  };
  auto valid = [&] {
    std::uint64_t n = 0;
    for (const cache::Texel& t : store_of(w.reg).cube(0).texels) n += t.valid() ? 1 : 0;
    return n;
  };
  fill();
  ASSERT_EQ(valid(), 6u * 16u * 16u);
  // In step: a frame where nothing moves outdates nothing.
  (void)frame(w);
  EXPECT_EQ(store_of(w.reg).counts().invalidated, 0u);
  EXPECT_EQ(valid(), 6u * 16u * 16u);

  // Syncs missed while nothing changed (another renderer's frames of a still scene, as the
  // bench interleaves them) lose nothing.
  std::shared_ptr<RayCacheStore> kept = std::move(w.reg.resource<cache::RayCaches>().store);
  (void)frame(w);
  (void)frame(w);
  w.reg.resource<cache::RayCaches>().store = std::move(kept);
  (void)frame(w);
  EXPECT_EQ(store_of(w.reg).counts().invalidated, 0u);
  ASSERT_EQ(valid(), 6u * 16u * 16u);

  kept = std::move(w.reg.resource<cache::RayCaches>().store);
  move(w.reg, two.a, vec3(0.0f, 0.0f, 10.0f));
  (void)frame(w);
  (void)frame(w); // a still sync after the move: the change is further back
  w.reg.resource<cache::RayCaches>().store = std::move(kept);
  (void)frame(w); // nothing moves in this sync
  EXPECT_EQ(valid(), 0u);
  // Back in step: refilled texels stay.
  fill();
  (void)frame(w);
  EXPECT_EQ(store_of(w.reg).counts().invalidated, 0u);
  EXPECT_EQ(valid(), 6u * 16u * 16u);
}

TEST(RayCacheInvalidation, AnOwnerThatMovesOutdatesItsWholeCube) {
  TwoSpheres two;
  World w;
  make_world(w, on(LookupMode::Direction, true), 16, [&](ecs::Registry& r) { two(r); }, 32);
  (void)frame(w);
  ASSERT_EQ(store_of(w.reg).counts().valid, 6u * 16u * 16u);
  move(w.reg, w.mirror, vec3(0.0f, 0.5f, 0.0f));
  (void)frame(w);
  EXPECT_EQ(store_of(w.reg).counts().invalidated, 6u * 16u * 16u);
  EXPECT_FLOAT_EQ(store_of(w.reg).cube(0).centre.y, 0.5f);
}

TEST(RayCacheInvalidation, ALightChangeOutdatesWhatItLightsNotTheSky) {
  World w;
  make_world(w, on(LookupMode::Direction, true), 16, [](ecs::Registry& r) {
    test::add_mesh(r, test::primitive("plane", 1.0f, vec3(40.0f)), test::at(vec3(0, -2, 0)),
                   diffuse(vec3(0.6f)));
  });
  const ecs::Entity light = test::add_point_light(w.reg, vec3(3, 8, 3), 100.0f);
  (void)frame(w);
  std::uint64_t surfaces = 0;
  for (const cache::Texel& t : store_of(w.reg).cube(0).texels)
    surfaces += std::isfinite(cache::texel_distance(t)) ? 1 : 0;
  ASSERT_GT(surfaces, 0u);
  ASSERT_LT(surfaces, 6u * 16u * 16u);
  w.reg.patch<Light>(light, [](Light& l) { l.intensity = 50.0f; });
  (void)frame(w);
  EXPECT_EQ(store_of(w.reg).counts().invalidated, surfaces);
}

/// A lit ground, the mirror, and a diffuse sphere C that will move into the mirror's view.
struct MovingIntoView {
  ecs::Entity c;
  void operator()(ecs::Registry& reg) {
    test::add_mesh(reg, test::primitive("plane", 1.0f, vec3(60.0f)), test::at(vec3(0, -1, 0)),
                   diffuse(vec3(0.55f, 0.55f, 0.5f)));
    test::add_point_light(reg, vec3(3, 10, 4), 150.0f);
    c = test::add_mesh(reg, test::primitive("sphere", 0.75f), test::at(vec3(0, 0, -30)),
                       diffuse(vec3(0.9f, 0.3f, 0.2f)), Kinematics::Type::Free);
  }
};

TEST(RayCacheInvalidation, AnEntityMovingIntoViewIsPickedUpAndLeavesNoStaleTexel) {
  for (const LookupMode mode : {LookupMode::Direction, LookupMode::Tau}) {
    SCOPED_TRACE(cache::lookup_mode_name(mode));
    MovingIntoView cached_build, reference_build;
    World cached, reference;
    make_world(cached, on(mode), 128, [&](ecs::Registry& r) { cached_build(r); });
    make_world(reference, CacheSettings{}, 128, [&](ecs::Registry& r) { reference_build(r); });
    double before = 0.0;
    for (int k = 0; k < 3; ++k) before = psnr(frame(cached), frame(reference));
    // Into the reflection, between the mirror and the camera's side, casting a shadow on the
    // ground the mirror shows.
    for (World* w : {&cached, &reference})
      move(w->reg, w == &cached ? cached_build.c : reference_build.c, vec3(1.2f, 0.0f, 2.5f));
    double after = 0.0;
    for (int k = 0; k < 3; ++k) after = psnr(frame(cached), frame(reference));
    EXPECT_GE(after, std::min(before, 60.0) - 0.5) << "before " << before << " dB";
    EXPECT_GT(store_of(cached.reg).counts().hits, 0u);
  }
}

TEST(RayCacheInvalidation, MovingOneHiddenSphereOutdatesUnderFivePercent) {
  Scene scene = load_scene(std::filesystem::path(SPECULA_SOURCE_DIR) /
                           "samples/scenes/mirror_spheres_32.json");
  ecs::Entity hidden = ecs::null_entity;
  scene.registry.view<Name>().each([&](ecs::Entity e, Name& n) {
    if (n.value.rfind("hidden sphere", 0) == 0)
      scene.registry.emplace_or_replace<Kinematics>(e, Kinematics{Kinematics::Type::Free});
    if (n.value == "hidden sphere 5") hidden = e;
  });
  ASSERT_NE(hidden, ecs::null_entity);
  RenderJob job;
  job.settings.max_depth = scene.settings.max_depth;
  job.settings.background = scene.settings.background;
  job.settings.threads = 2;
  job.image = Framebuffer(32, 32);
  job.cache = on(LookupMode::Direction, true);
  prepare_rendering(scene.registry, std::move(job));
  Schedule schedule;
  schedule.tick(scene.registry, 0.0);
  RayCacheStore& store = store_of(scene.registry);
  ASSERT_EQ(store.counts().valid, store.counts().texels);
  scene.registry.patch<Transform>(hidden, [](Transform& t) { t.translation.x += 0.3f; });
  schedule.tick(scene.registry, 0.0);
  const CacheCounts& c = store.counts();
  EXPECT_GT(c.invalidated, 0u);
  EXPECT_LT(double(c.invalidated), 0.05 * double(c.texels));
  EXPECT_EQ(c.flush_all, c.texels);
}

// ---------------------------------------------------------------------------------------------
// Frames, budgets and the policy

TEST(RayCache, FramesAndTexelsAreTheSameWhateverTheThreadCount) {
  for (const LookupMode mode : {LookupMode::Direction, LookupMode::Tau, LookupMode::March}) {
    SCOPED_TRACE(cache::lookup_mode_name(mode));
    MovingIntoView b1, b2;
    World one, two;
    make_world(one, on(mode), 64, [&](ecs::Registry& r) { b1(r); }, 64, vec3(0.0f, 0.3f, 4.0f), 1);
    make_world(two, on(mode), 64, [&](ecs::Registry& r) { b2(r); }, 64, vec3(0.0f, 0.3f, 4.0f), 2);
    one.reg.resource<RenderJob>().settings.tile_size = 8;
    for (int k = 0; k < 3; ++k) {
      const Framebuffer a = frame(one);
      const Framebuffer b = frame(two);
      ASSERT_EQ(rmse(a, b), 0.0) << "frame " << k;
      orbit(one, 2.0f);
      orbit(two, 2.0f);
    }
    const auto ta = store_of(one.reg).cube(0).texels;
    const auto tb = store_of(two.reg).cube(0).texels;
    ASSERT_EQ(ta.size(), tb.size());
    EXPECT_EQ(std::memcmp(ta.data(), tb.data(), ta.size_bytes()), 0);
  }
}

TEST(RayCache, TheFillBudgetBoundsTexelsWrittenPerFrame) {
  CacheSettings s = on(LookupMode::Direction);
  s.fill_budget = 100;
  World w;
  make_world(w, s, 128, distant_surroundings);
  std::uint64_t valid = 0;
  for (int k = 0; k < 4; ++k) {
    (void)frame(w);
    const CacheCounts& c = store_of(w.reg).counts();
    EXPECT_LE(c.written, 100u);
    EXPECT_EQ(c.valid, valid + c.written);
    valid = c.valid;
  }
  EXPECT_EQ(valid, 400u);
}

/// Fill ahead's tile of texel i on a cube of `res` (RayCacheStore::kFillAheadTiles a face side).
std::uint32_t fill_tile(std::uint32_t i, std::uint32_t res) {
  const std::uint32_t side = std::min(res, RayCacheStore::kFillAheadTiles), size = res / side;
  const std::uint32_t face = i / (res * res), within = i % (res * res);
  return (face * side + (within / res) / size) * side + (within % res) / size;
}

TEST(RayCache, FillAheadTracesItsBudgetInTheTilesTheLookupsAddressedFirst) {
  constexpr std::uint32_t kRes = 512, kBudget = 300;
  CacheSettings s = on(LookupMode::Direction);
  s.fill_ahead = kBudget;
  World w;
  make_world(w, s, kRes, distant_surroundings);
  (void)frame(w);
  // Before the first frame nothing was looked up: nothing is filled ahead. Every lookup found
  // an outdated texel and wrote it, so the tiles addressed are those of the valid texels.
  EXPECT_EQ(store_of(w.reg).counts().prefilled, 0u);
  std::vector<std::uint8_t> addressed(6u * 64u * 64u, 0);
  std::uint64_t written = 0;
  {
    const auto texels = store_of(w.reg).cube(0).texels;
    for (std::uint32_t i = 0; i < texels.size(); ++i)
      if (texels[i].valid()) {
        addressed[fill_tile(i, kRes)] = 1;
        ++written;
      }
  }
  ASSERT_GT(written, 0u);
  (void)frame(w);
  // Before the second: the budget, all of it in those tiles (each has 64 texels, the lookups
  // of a 96² image wrote only a few of them), traced from the centre.
  EXPECT_EQ(store_of(w.reg).counts().prefilled, kBudget);
  const auto texels = store_of(w.reg).cube(0).texels;
  std::uint64_t ahead = 0;
  for (std::uint32_t i = 0; i < texels.size(); ++i) {
    if (!texels[i].valid() || (texels[i].state & cache::kTexelPrefilled) == 0) continue;
    ++ahead;
    EXPECT_TRUE(addressed[fill_tile(i, kRes)]) << "texel " << i << " is in a tile not looked up";
  }
  EXPECT_EQ(ahead, kBudget);
}

/// Direction mode with fill ahead K, 128² faces, distant surroundings.
void fill_ahead_world(World& w, std::uint32_t ahead) {
  CacheSettings s = on(LookupMode::Direction);
  s.fill_ahead = ahead;
  make_world(w, s, 128, distant_surroundings);
}

TEST(RayCache, FillAheadLetsAPanningViewFindTheDirectionsItTurnsToValid) {
  // The camera orbits 3° a frame (about four texels of 128² faces): without fill ahead most
  // lookups of the next frame find outdated texels; with it (rings of tiles around the last
  // frame's lookups, half the cube a frame), almost none do.
  auto outdated_share = [](std::uint32_t ahead) {
    World w;
    fill_ahead_world(w, ahead);
    double share = 0.0;
    for (int k = 0; k < 4; ++k) {
      (void)frame(w);
      const CacheCounts& c = store_of(w.reg).counts();
      // Direction mode serves every valid texel: what it did not serve was outdated.
      share = double(c.lookups - c.hits) / double(std::max<std::uint64_t>(1, c.lookups));
      orbit(w, 3.0f);
    }
    return share;
  };
  const double without = outdated_share(0);
  const double with = outdated_share(6u * 128u * 128u / 2u);
  EXPECT_GT(without, 0.3);
  EXPECT_LT(with, 0.02);
}

TEST(RayCache, FillAheadsRaysAreChargedAgainstWhatTheCubeSaves) {
  // A still camera looks up the same directions every frame: from the second frame on it is
  // served whole, with or without fill ahead (which fills texels it does not look up). The
  // rays fill ahead traces come off what the cube is said to save.
  auto saved_ms = [](std::uint32_t ahead) {
    World w;
    fill_ahead_world(w, ahead);
    (void)frame(w);
    (void)frame(w);
    const CacheCounts& c = store_of(w.reg).counts();
    EXPECT_EQ(c.hits, c.lookups);
    EXPECT_EQ(c.prefilled, ahead);
    return c.cubes.at(0).saved_ms;
  };
  EXPECT_GT(saved_ms(0), 0.0);
  EXPECT_LT(saved_ms(50000), 0.0);
}

TEST(RayCache, PrefillFillsEveryTexelOfACubeLargerThanOneBatch) {
  // 6·128² = 98 304 texels: traced in batches of 65 536, every one filled once.
  World w;
  make_world(w, on(LookupMode::Direction, true), 128, distant_surroundings);
  (void)frame(w);
  const CacheCounts& c = store_of(w.reg).counts();
  EXPECT_EQ(c.prefilled, 6u * 128u * 128u);
  EXPECT_EQ(c.valid, 6u * 128u * 128u);
  const auto texels = store_of(w.reg).cube(0).texels;
  for (std::size_t i = 0; i < texels.size(); ++i)
    ASSERT_NE(texels[i].state & cache::kTexelPrefilled, 0) << "texel " << i;
}

TEST(RayCache, FillAheadIsTheSameWhateverTheThreadCount) {
  CacheSettings s = on(LookupMode::Direction);
  s.fill_ahead = 5000;
  World one, two;
  make_world(one, s, 128, distant_surroundings, 64, vec3(0.0f, 0.3f, 4.0f), 1);
  make_world(two, s, 128, distant_surroundings, 64, vec3(0.0f, 0.3f, 4.0f), 2);
  one.reg.resource<RenderJob>().settings.tile_size = 8;
  for (int k = 0; k < 3; ++k) {
    const Framebuffer a = frame(one);
    const Framebuffer b = frame(two);
    ASSERT_EQ(rmse(a, b), 0.0) << "frame " << k;
    EXPECT_EQ(store_of(one.reg).counts().prefilled, store_of(two.reg).counts().prefilled);
    orbit(one, 2.0f);
    orbit(two, 2.0f);
  }
  EXPECT_GT(store_of(one.reg).counts().prefilled, 0u);
  const auto ta = store_of(one.reg).cube(0).texels;
  const auto tb = store_of(two.reg).cube(0).texels;
  ASSERT_EQ(ta.size(), tb.size());
  EXPECT_EQ(std::memcmp(ta.data(), tb.data(), ta.size_bytes()), 0);
}

TEST(RayCachePolicy, AutoKeepsCachingWhereItPaysWithinTheBound) {
  CacheSettings s;
  s.policy = CachePolicy::Auto;
  s.max_error_db = 40.0;
  World cached, reference;
  make_world(cached, s, 256, distant_surroundings);
  make_world(reference, CacheSettings{}, 256, distant_surroundings);
  Framebuffer a{1, 1}, b{1, 1};
  for (int k = 0; k < 8; ++k) {
    a = frame(cached);
    b = frame(reference);
  }
  const CacheCounts& c = store_of(cached.reg).counts();
  ASSERT_EQ(c.cubes.size(), 1u);
  EXPECT_EQ(c.cubes[0].mode, "direction") << c.cubes[0].reason;
  EXPECT_GE(c.cubes[0].estimated_psnr_db, 40.0);
  EXPECT_GT(c.hits, 0u);
  EXPECT_GE(psnr(a, b), 40.0);
}

TEST(RayCachePolicy, AutoOnTheMirrorSpheresKeepsTheBoundOrStopsCaching) {
  Scene scene = load_scene(std::filesystem::path(SPECULA_SOURCE_DIR) /
                           "samples/scenes/mirror_spheres_32.json");
  Scene reference = load_scene(std::filesystem::path(SPECULA_SOURCE_DIR) /
                               "samples/scenes/mirror_spheres_32.json");
  for (Scene* sc : {&scene, &reference}) {
    RenderJob job;
    job.settings.max_depth = sc->settings.max_depth;
    job.settings.background = sc->settings.background;
    job.settings.threads = 2;
    job.image = Framebuffer(96, 96);
    if (sc == &scene) job.cache.policy = CachePolicy::Auto;
    prepare_rendering(sc->registry, std::move(job));
  }
  Schedule s1, s2;
  for (int k = 0; k < 12; ++k) {
    s1.tick(scene.registry, 0.0);
    s2.tick(reference.registry, 0.0);
  }
  const CacheCounts& c = store_of(scene.registry).counts();
  ASSERT_EQ(c.cubes.size(), 1u);
  const CubeReport& r = c.cubes[0];
  EXPECT_FALSE(r.reason.empty());
  if (r.mode != "off") {
    EXPECT_GE(r.estimated_psnr_db, 40.0) << r.reason;
    EXPECT_GT(r.saved_ms, 0.0) << r.reason;
  } else {
    EXPECT_EQ(c.lookups, 0u) << "an off cube costs no lookups";
    EXPECT_EQ(scene.registry.resource<RenderJob>().last.rays,
              reference.registry.resource<RenderJob>().last.rays)
        << "off: the frame traces what uncached tracing traces";
  }
  EXPECT_GE(psnr(scene.registry.resource<RenderJob>().image,
                 reference.registry.resource<RenderJob>().image),
            40.0)
      << r.mode << ": " << r.reason;
}

/// Drives a store's auto policy frame by frame with made-up leaving rays: every valid texel of
/// cube 0 looked up once, from the owner's surface along the texel's direction; a verified ray
/// comes back `error` off in each channel (large while "the camera moves", 0 once it rests).
/// Returns the cube's report after the frame.
CubeReport policy_frame(RayCacheStore& store, float error) {
  const cache::CubeView cube = store.cube(0);
  std::vector<LeavingQuery> queries;
  for (std::uint32_t i = 0; i < cube.texels.size(); ++i) {
    if (!cube.texels[i].valid()) continue;
    const vec3 d = cache::texel_direction(i, cube.resolution);
    queries.push_back(LeavingQuery{cube.instance, i, 1, cube.centre + d * 1.001f, d});
  }
  store.begin_frame(64, 64, TraceMode::Whitted);
  std::vector<CachedRadiance> answers(queries.size());
  if (store.wants_lookups()) store.lookup(queries, answers);
  std::vector<LeavingRadiance> rays;
  for (std::size_t k = 0; k < queries.size(); ++k) {
    LeavingRadiance r{};
    r.from = cube.owner;
    r.instance = cube.instance;
    r.kind = RayKind::Reflection;
    r.exits = true;
    r.answer = answers[k].answer;
    r.depth = 1;
    r.pixel = queries[k].pixel;
    r.origin = queries[k].origin;
    r.direction = queries[k].direction;
    r.weight = r.throughput = vec3(1.0f);
    r.cached = answers[k].radiance;
    r.radiance = r.answer == CacheAnswer::Use ? r.cached : r.cached + vec3(error);
    r.hit_t = std::numeric_limits<float>::infinity();
    r.hit_entity = kNoInstance;
    r.rays = r.answer == CacheAnswer::Use ? 0u : 1u;
    rays.push_back(r);
  }
  store.leaving(rays);
  store.end_frame(1.0, 4 * queries.size());
  return store.counts().cubes.at(0);
}

TEST(RayCachePolicy, AutoRetriesAModeThatMissedTheBoundOnceItMayBeWithinAgain) {
  // A direction cache's error depends on where the camera has been: it leaves direction mode
  // while the camera moves, and kRetryFrames frames after it is off it tries direction again —
  // kept if the error is within the bound now, back off at once if not.
  CacheSettings s;
  s.policy = CachePolicy::Auto;
  World w;
  make_world(w, s, 16, distant_surroundings, 64);
  (void)frame(w); // the cube made and filled where the camera looks
  RayCacheStore& store = store_of(w.reg);
  ASSERT_GT(store.counts().valid, 100u);
  // Moving: every mode misses the bound, down the ladder to off.
  CubeReport r;
  int frames = 0;
  for (; frames < 60; ++frames) {
    r = policy_frame(store, 1.0f);
    if (r.mode == "off") break;
  }
  ASSERT_EQ(r.mode, "off") << r.reason;
  // Resting: off until the retry, then direction within the bound, kept.
  int off_frames = 0;
  for (;;) {
    r = policy_frame(store, 0.0f);
    if (r.mode != "off") break;
    ASSERT_LT(++off_frames, 100) << "never retried: " << r.reason;
  }
  EXPECT_EQ(off_frames + 1, 32) << "the retry comes kRetryFrames frames after the cube went off";
  EXPECT_EQ(r.mode, "direction");
  EXPECT_NE(r.reason.find("trying it again"), std::string::npos) << r.reason;
  for (int k = 0; k < 8; ++k) r = policy_frame(store, 0.0f);
  EXPECT_EQ(r.mode, "direction") << r.reason;
  EXPECT_NE(r.reason.find("kept"), std::string::npos) << r.reason;
  // Moving again: direction missed; its retries find it still outside and go back off at once.
  for (int k = 0; k < 60 && r.mode != "off"; ++k) r = policy_frame(store, 1.0f);
  ASSERT_EQ(r.mode, "off") << r.reason;
  for (int k = 0; k < 40; ++k) r = policy_frame(store, 1.0f);
  EXPECT_EQ(r.mode, "off");
  EXPECT_NE(r.reason.find("below the 40.0 dB bound again"), std::string::npos) << r.reason;
}

// ---------------------------------------------------------------------------------------------
// Path mode: a texel is a probe of the radiance that the surface its direction hits scatters
// towards the object (docs/design/ray-cache.md, "Path mode").

/// Far diffuse spheres over a ground, lit by a point light, and one far emitter: a ray leaving
/// the mirror meets surfaces whose scattered radiance is a noisy path estimate, or a light whose
/// emission the traced ray gives exactly.
struct LitSurroundings {
  ecs::Entity lamp;
  void operator()(ecs::Registry& reg) {
    const vec3 colours[] = {vec3(0.8f, 0.3f, 0.2f), vec3(0.2f, 0.7f, 0.3f), vec3(0.3f, 0.4f, 0.8f),
                            vec3(0.8f, 0.8f, 0.3f), vec3(0.7f, 0.3f, 0.7f)};
    const vec3 where[] = {vec3(40, 6, 0), vec3(-40, 0, 10), vec3(0, 10, 40), vec3(6, -4, -40),
                          vec3(-28, 14, -28)};
    for (int i = 0; i < 5; ++i)
      test::add_mesh(reg, test::primitive("sphere", 12.0f), test::at(where[i]),
                     diffuse(colours[i]));
    test::add_mesh(reg, test::primitive("plane", 1.0f, vec3(400.0f)), test::at(vec3(0, -30, 0)),
                   diffuse(vec3(0.5f)));
    test::add_point_light(reg, vec3(10, 80, 20), 8000.0f);
    lamp = test::add_mesh(reg, test::primitive("sphere", 8.0f), test::at(vec3(30, 24, 30)),
                          emissive(vec3(3.0f, 2.6f, 2.2f)));
  }
};

/// Forwards everything to the store and keeps the leaving rays it was handed.
class Tap final : public RadianceHook {
public:
  explicit Tap(std::shared_ptr<RayCacheStore> store) : store_(std::move(store)) {}
  void begin_frame(std::uint32_t w, std::uint32_t h, TraceMode mode) override {
    store_->begin_frame(w, h, mode);
  }
  [[nodiscard]] bool wants_lookups() const override { return store_->wants_lookups(); }
  [[nodiscard]] bool wants_leaving() const override { return store_->wants_leaving(); }
  void lookup(std::span<const LeavingQuery> q, std::span<CachedRadiance> a) const override {
    store_->lookup(q, a);
  }
  void leaving(std::span<const LeavingRadiance> rays) override {
    {
      const std::lock_guard lock(mutex_);
      rays_.insert(rays_.end(), rays.begin(), rays.end());
    }
    store_->leaving(rays);
  }
  void end_frame(double ms, std::uint64_t rays) override { store_->end_frame(ms, rays); }
  void report(CacheCounts& out) const override { store_->report(out); }
  std::vector<LeavingRadiance> rays_;

private:
  std::shared_ptr<RayCacheStore> store_;
  std::mutex mutex_;
};

/// The world's job switched to path mode (1 sample per pixel per frame, accumulated).
void path_mode(World& w, std::uint32_t seed = 0) {
  RenderJob& job = w.reg.resource<RenderJob>();
  job.settings.mode = TraceMode::Path;
  job.settings.spp = 1;
  job.settings.seed = seed;
}

/// Two path-mode worlds of one scene, each made by `make(world, cache settings)`: `cached` with
/// `cache`, `uncached` without.
template <class Make>
void path_worlds(World& cached, World& uncached, const CacheSettings& cache, Make make) {
  make(cached, cache);
  make(uncached, CacheSettings{});
  path_mode(cached);
  path_mode(uncached);
}

/// As above, and `third` without a cache under seed `seed` (a reference, or an estimate
/// independent of `uncached`).
template <class Make>
void path_worlds(World& cached, World& uncached, World& third, const CacheSettings& cache,
                 std::uint32_t seed, Make make) {
  path_worlds(cached, uncached, cache, make);
  make(third, CacheSettings{});
  path_mode(third, seed);
}

/// Path mode with the texels' probes serving (--cache-serve on) and, unless asked, without the
/// incoming-light probe (so that a pixel is its own part plus what the texels gave).
CacheSettings path_cache(std::uint32_t samples, std::uint32_t refresh = 2,
                         bool irradiance = false) {
  CacheSettings s = on(LookupMode::Direction);
  s.path_serve = true;
  s.path_irradiance = irradiance;
  s.path_samples = samples;
  s.path_refresh = refresh;
  return s;
}

/// The sum of a's pixel components over b's: whether two images are as bright.
double brightness_ratio(const Framebuffer& a, const Framebuffer& b) {
  double sa = 0.0, sb = 0.0;
  for (std::size_t i = 0; i < a.pixel_count(); ++i) {
    sa += double(a.pixels()[i].x + a.pixels()[i].y + a.pixels()[i].z);
    sb += double(b.pixels()[i].x + b.pixels()[i].y + b.pixels()[i].z);
  }
  return sa / sb;
}

bool served(const LeavingRadiance& r) {
  return r.answer == CacheAnswer::Use || r.answer == CacheAnswer::Refresh;
}

TEST(RayCachePathMode, TheIrradianceOfTheIncomingProbeIsExactForLightOfOrderOne) {
  // Light arriving from above only (L = 1 where s.y > 0): the irradiance (1/π)∫ L max(0, n·s)
  // is (1 + n.y) / 2, linear in n, which nine spherical harmonics hold exactly (up to the cells'
  // quadrature). A uniform sphere of light gives its radiance in every direction.
  constexpr std::uint32_t side = 16;
  std::vector<cache::IncomingCell> above(6 * side * side), uniform(6 * side * side);
  for (std::uint32_t i = 0; i < above.size(); ++i) {
    const vec3 s = cache::texel_direction(i, side);
    const float l = s.y > 0.0f ? 1.0f : 0.0f;
    above[i] = cache::IncomingCell{{l, 2.0f * l, 0.5f * l}, 1.0f};
    uniform[i] = cache::IncomingCell{{0.6f, 1.2f, 1.8f}, 2.0f}; // radiance (0.3, 0.6, 0.9)
  }
  float coverage = 0.0f;
  const cache::IrradianceSH sky = cache::project_irradiance(above, side, coverage);
  EXPECT_NEAR(coverage, 1.0f, 1e-5f);
  for (const vec3 n : {vec3(0, 1, 0), vec3(0, -1, 0), vec3(1, 0, 0), glm::normalize(vec3(1, 1, 0)),
                       glm::normalize(vec3(-1, -2, 3))}) {
    const vec3 e = sky.evaluate(n);
    const float want = 0.5f * (1.0f + n.y);
    EXPECT_NEAR(e.x, want, 0.02f) << n.x << " " << n.y << " " << n.z;
    EXPECT_NEAR(e.y, 2.0f * want, 0.04f);
    EXPECT_NEAR(e.z, 0.5f * want, 0.01f);
  }
  const cache::IrradianceSH all = cache::project_irradiance(uniform, side, coverage);
  for (const vec3 n : {vec3(0, 0, 1), glm::normalize(vec3(2, -1, 0.5f))}) {
    const vec3 e = all.evaluate(n);
    EXPECT_NEAR(e.x, 0.3f, 0.003f);
    EXPECT_NEAR(e.y, 0.6f, 0.006f);
    EXPECT_NEAR(e.z, 0.9f, 0.009f);
  }
  // Unsampled cells take the mean of the sampled ones, and say how much was sampled.
  for (std::uint32_t i = 0; i < uniform.size(); ++i)
    if (cache::texel_direction(i, side).x > 0.5f) uniform[i] = cache::IncomingCell{};
  const cache::IrradianceSH part = cache::project_irradiance(uniform, side, coverage);
  EXPECT_GT(coverage, 0.6f);
  EXPECT_LT(coverage, 0.95f);
  EXPECT_NEAR(part.evaluate(vec3(1, 0, 0)).y, 0.6f, 0.006f);
}

TEST(RayCachePathMode, TheIncomingProbeLightsTheDiffuseLobeWithLessErrorAndNoBias) {
  // A half-diffuse mirror (reflectivity 0.5) far from everything: with the incoming-light probe
  // its diffuse lobe takes the probe's irradiance instead of a sampled bounce. Against a
  // reference of many uncached frames, 16 frames have less error on the mirror with it than
  // without, and the image's mean stays that of uncached tracing (no bias beyond the probe's
  // coarse cells).
  LitSurroundings lit;
  const auto build = [&](ecs::Registry& r) { lit(r); };
  const Material half = mirror_material(0.5f);
  CacheSettings probe = on(LookupMode::Direction); // path mode's defaults: irradiance, no serving
  World cached, uncached, reference;
  path_worlds(cached, uncached, reference, probe, 11, [&](World& w, const CacheSettings& cs) {
    make_world(w, cs, 16, build, 48, vec3(0.0f, 0.3f, 4.0f), 2, half);
  });
  Framebuffer a{1, 1}, b{1, 1}, ref{1, 1};
  for (int k = 0; k < 16; ++k) {
    a = frame(cached);
    b = frame(uncached);
  }
  for (int k = 0; k < 512; ++k) ref = frame(reference);
  EXPECT_FALSE(store_of(cached.reg).wants_lookups()); // nothing is served from the texels
  EXPECT_TRUE(store_of(cached.reg).cube(0).lights_diffuse);
  // On the mirror (the middle 40% of the image, all sphere), against the reference.
  const auto mirror_rmse = [&](const Framebuffer& x) {
    double sum = 0.0;
    std::size_t n = 0;
    for (std::uint32_t y = 29 * 48 / 100; y < 69 * 48 / 100; ++y)
      for (std::uint32_t x0 = 29 * 48 / 100; x0 < 69 * 48 / 100; ++x0) {
        const vec3 d = x.pixels()[y * 48 + x0] - ref.pixels()[y * 48 + x0];
        sum += double(glm::dot(d, d));
        ++n;
      }
    return std::sqrt(sum / double(3 * n));
  };
  EXPECT_LT(mirror_rmse(a), 0.9 * mirror_rmse(b))
      << "cached " << mirror_rmse(a) << ", uncached " << mirror_rmse(b);
  EXPECT_NEAR(brightness_ratio(a, ref), 1.0, 0.02);
}

TEST(RayCachePathMode, TheIncomingProbeIsTheSameWhateverTheThreadCount) {
  LitSurroundings l1, l2;
  World one, two;
  const Material half = mirror_material(0.5f);
  make_world(
      one, on(LookupMode::Direction), 16, [&](ecs::Registry& r) { l1(r); }, 48,
      vec3(0.0f, 0.3f, 4.0f), 1, half);
  make_world(
      two, on(LookupMode::Direction), 16, [&](ecs::Registry& r) { l2(r); }, 48,
      vec3(0.0f, 0.3f, 4.0f), 2, half);
  one.reg.resource<RenderJob>().settings.tile_size = 8;
  path_mode(one);
  path_mode(two);
  for (int k = 0; k < 3; ++k) ASSERT_EQ(rmse(frame(one), frame(two)), 0.0) << "frame " << k;
  const auto a = store_of(one.reg).cube(0).incoming, b = store_of(two.reg).cube(0).incoming;
  ASSERT_FALSE(a.empty());
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(std::memcmp(a.data(), b.data(), a.size_bytes()), 0);
}

TEST(RayCachePathMode, ProbesAverageTheSamplesOfOneSurfaceBatchByBatch) {
  // The store's probes against a model fed with the leaving rays themselves, frame by frame: a
  // texel's surface is its first sample's hit entity (first in pixel, sample, depth, kind and
  // direction order); each frame's samples of that surface join a moving average with weight
  // (1 − α) for what it held; the lookups its direction had are kept; it serves while the
  // average's weight reaches path_samples.
  World w;
  LitSurroundings lit;
  // Coarse texels (several lookups each), so that most served lookups are not refreshed.
  make_world(
      w, path_cache(3, 1), 8, [&](ecs::Registry& r) { lit(r); }, 64);
  path_mode(w);
  auto tap = std::make_shared<Tap>(w.reg.resource<cache::RayCaches>().store);
  w.reg.resource<RenderJob>().hook = tap;
  const std::uint32_t resolution = 8;
  const std::size_t texels = std::size_t(cache::kFaceCount) * resolution * resolution;
  struct Model {
    glm::dvec3 sum{0.0};
    double weight = 0.0;
    std::uint32_t samples = 0, lookups = 0, surface = kNoInstance;
  };
  std::vector<Model> model(texels);
  std::size_t served_rays = 0, refreshed = 0, other_surface = 0, served_elsewhere = 0;
  for (int k = 0; k < 6; ++k) {
    tap->rays_.clear();
    (void)frame(w);
    std::vector<std::vector<const LeavingRadiance*>> by_texel(texels);
    for (const LeavingRadiance& r : tap->rays_) {
      ASSERT_TRUE(r.exits);
      by_texel[cache::texel_of(r.direction, resolution)].push_back(&r);
      served_rays += served(r) ? 1 : 0;
      refreshed += r.answer == CacheAnswer::Refresh ? 1 : 0;
    }
    const cache::CubeView cube = store_of(w.reg).cube(0);
    ASSERT_EQ(cube.probe.size(), texels);
    for (std::size_t i = 0; i < texels; ++i) {
      auto& rays = by_texel[i];
      if (rays.empty()) continue;
      std::sort(rays.begin(), rays.end(), [](const LeavingRadiance* a, const LeavingRadiance* b) {
        const auto key = [](const LeavingRadiance* r) {
          std::uint32_t x, y;
          std::memcpy(&x, &r->direction.x, 4);
          std::memcpy(&y, &r->direction.y, 4);
          return std::tuple(r->pixel, (r->sample << 12) | (r->depth << 4) | std::uint32_t(r->kind),
                            (std::uint64_t(x) << 32) | y);
        };
        return key(a) < key(b);
      });
      Model& m = model[i];
      // A served ray hit the surface of its texel's probe.
      for (const LeavingRadiance* r : rays)
        if (served(*r) && r->hit_entity != m.surface) ++served_elsewhere;
      glm::dvec3 batch(0.0);
      std::uint32_t n = 0;
      for (const LeavingRadiance* r : rays) {
        if (r->answer == CacheAnswer::Use) continue;
        if (m.samples == 0 && n == 0) m.surface = r->hit_entity;
        if (r->hit_entity != m.surface) {
          ++other_surface;
          continue;
        }
        batch += glm::dvec3(r->radiance);
        ++n;
      }
      m.lookups = std::uint32_t(rays.size());
      if (n > 0) {
        m.sum = m.sum * double(1.0f - cache::kProbeDecay) + batch;
        m.weight = m.weight * double(1.0f - cache::kProbeDecay) + double(n);
        m.samples += n;
      }
      const cache::ProbeTexel& p = cube.probe[i];
      ASSERT_EQ(p.samples, m.samples) << "frame " << k << ", texel " << i;
      ASSERT_EQ(p.lookups, m.lookups) << "frame " << k << ", texel " << i;
      if (m.samples == 0) continue;
      ASSERT_EQ(cube.texels[i].hit, m.surface) << "frame " << k << ", texel " << i;
      EXPECT_NEAR(p.weight, m.weight, 1e-4 * m.weight);
      for (int c = 0; c < 3; ++c) EXPECT_NEAR(p.sum[c], m.sum[c], 1e-4 * (1.0 + m.sum[c]));
      EXPECT_EQ(cube.texels[i].valid(), m.weight >= 3.0) << "frame " << k << ", texel " << i;
      // The texel's colour is the mean (in half precision).
      const vec3 colour = cache::texel_radiance(cube.texels[i]);
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(colour[c], m.sum[c] / m.weight, 2e-3 * (1.0 + m.sum[c] / m.weight));
    }
  }
  EXPECT_GT(served_rays, 100u) << "valid texels serve the later frames' samples";
  EXPECT_GT(refreshed, 10u) << "and some of those are traced on for the probe";
  EXPECT_LT(refreshed, served_rays / 2);
  EXPECT_GT(other_surface, 0u) << "texels on silhouettes must see both surfaces";
  EXPECT_EQ(served_elsewhere, 0u) << "a texel serves only rays that hit its probe's surface";
}

TEST(RayCachePathMode, ASampleTakesEmissionAndTheCachedValueAndRefreshedPathsStayOutOfIt) {
  // A perfect mirror (no diffuse part, so nothing at the primary vertex): a mirror pixel is
  // throughput × (emission at the leaving ray's hit + what comes after it). Traced on, that is
  // the record's radiance; served or refreshed, the cached value alone — what a refreshed path
  // gathers afterwards must not reach the image. Frames not accumulated.
  World w;
  LitSurroundings lit;
  make_world(
      w, path_cache(2, 1), 8, [&](ecs::Registry& r) { lit(r); }, 64, vec3(0.0f, 0.3f, 4.0f), 2,
      mirror_material(1.0f));
  path_mode(w);
  w.reg.resource<RenderJob>().accumulate = false;
  auto tap = std::make_shared<Tap>(w.reg.resource<cache::RayCaches>().store);
  w.reg.resource<RenderJob>().hook = tap;
  const vec3 lamp = vec3(3.0f, 2.6f, 2.2f);
  std::size_t checked = 0, lamp_hits = 0, mismatched = 0;
  std::map<CacheAnswer, std::size_t> by_answer;
  for (int k = 0; k < 5; ++k) {
    tap->rays_.clear();
    const Framebuffer image = frame(w);
    std::vector<int> first(image.pixel_count(), -1);
    for (std::size_t j = 0; j < tap->rays_.size(); ++j)
      if (tap->rays_[j].depth == 1) {
        ASSERT_EQ(first[tap->rays_[j].pixel], -1) << "one sample: one ray leaves a pixel's hit";
        first[tap->rays_[j].pixel] = int(j);
      }
    for (std::size_t p = 0; p < image.pixel_count(); ++p) {
      if (first[p] < 0) continue;
      const LeavingRadiance& r = tap->rays_[std::size_t(first[p])];
      const vec3 emitted = r.hit_entity == lit.lamp.index ? lamp : vec3(0.0f);
      lamp_hits += r.hit_entity == lit.lamp.index ? 1 : 0;
      const vec3 expected = r.throughput * (emitted + (served(r) ? r.cached : r.radiance));
      const vec3 got = image.pixels()[p];
      if (glm::any(glm::greaterThan(glm::abs(expected - got), 1e-5f * glm::abs(got) + vec3(1e-6f))))
        ++mismatched;
      ++checked;
      ++by_answer[r.answer];
    }
  }
  EXPECT_GT(checked, 1000u);
  EXPECT_EQ(mismatched, 0u);
  EXPECT_GT(lamp_hits, 5u) << "the lamp must be seen in the mirror";
  EXPECT_GT(by_answer[CacheAnswer::Trace], 100u);
  EXPECT_GT(by_answer[CacheAnswer::Use], 100u);
  EXPECT_GT(by_answer[CacheAnswer::Refresh], 20u);
}

TEST(RayCachePathMode, ServedSamplesEndAtTheirFirstHitAndTheImageConvergesToUncached) {
  // A texel's mean is what paths scattered towards the mirror from its surface bring back, so
  // the cached image converges to the uncached one (within the texel's blur, small against the
  // noise here); served samples trace nothing after the leaving ray's hit.
  LitSurroundings lit;
  World cached, uncached, other_seed;
  const auto build = [&](ecs::Registry& r) { lit(r); };
  path_worlds(cached, uncached, other_seed, path_cache(4, 1), 7,
              [&](World& w, const CacheSettings& cs) { make_world(w, cs, 16, build, 64); });
  Framebuffer a{1, 1}, b{1, 1}, c{1, 1};
  for (int k = 0; k < 64; ++k) {
    a = frame(cached);
    b = frame(uncached);
    c = frame(other_seed);
  }
  const FrameStats& last = cached.reg.resource<RenderJob>().last;
  const FrameStats& plain = uncached.reg.resource<RenderJob>().last;
  EXPECT_GT(last.cache.hits, last.cache.lookups / 2);
  EXPECT_LT(last.rays[RayKind::Shadow], plain.rays[RayKind::Shadow]);
  EXPECT_LT(last.rays.total(), plain.rays.total());
  // The cache's error against uncached is of the order of the noise between two uncached runs.
  const double noise = psnr(b, c);
  EXPECT_GE(psnr(a, b), noise - 3.0) << "two uncached seeds: " << noise << " dB";
  EXPECT_NEAR(brightness_ratio(a, b), 1.0, 0.02);
}

TEST(RayCachePathMode, FramesAndProbesAreTheSameWhateverTheThreadCount) {
  LitSurroundings lit;
  const auto build = [&](ecs::Registry& r) { lit(r); };
  World one, two;
  make_world(one, path_cache(2), 16, build, 48, vec3(0.0f, 0.3f, 4.0f), 1);
  make_world(two, path_cache(2), 16, build, 48, vec3(0.0f, 0.3f, 4.0f), 2);
  path_mode(one);
  path_mode(two);
  one.reg.resource<RenderJob>().settings.tile_size = 8;
  for (int k = 0; k < 4; ++k) {
    ASSERT_EQ(rmse(frame(one), frame(two)), 0.0) << "frame " << k;
    orbit(one, 2.0f);
    orbit(two, 2.0f);
  }
  const cache::CubeView a = store_of(one.reg).cube(0), b = store_of(two.reg).cube(0);
  ASSERT_EQ(a.probe.size(), b.probe.size());
  EXPECT_GT(store_of(one.reg).counts().hits, 0u);
  EXPECT_EQ(std::memcmp(a.probe.data(), b.probe.data(), a.probe.size_bytes()), 0);
  EXPECT_EQ(std::memcmp(a.texels.data(), b.texels.data(), a.texels.size_bytes()), 0);
}

TEST(RayCachePathMode, SwitchingBetweenWhittedAndPathStartsTheCubesAfresh) {
  LitSurroundings lit;
  World w;
  make_world(
      w, path_cache(2), 16, [&](ecs::Registry& r) { lit(r); }, 48);
  for (int k = 0; k < 2; ++k) (void)frame(w); // Whitted: exact values, no indirect light
  ASSERT_GT(store_of(w.reg).counts().valid, 0u);
  path_mode(w);
  (void)frame(w);
  const cache::CubeView cube = store_of(w.reg).cube(0);
  ASSERT_EQ(cube.probe.size(), cube.texels.size());
  for (std::size_t i = 0; i < cube.texels.size(); ++i) {
    if (cube.texels[i].valid()) {
      ASSERT_GE(cube.probe[i].weight, 2.0f) << "a Whitted value survived";
    }
  }
  w.reg.resource<RenderJob>().settings.mode = TraceMode::Whitted;
  (void)frame(w);
  EXPECT_TRUE(store_of(w.reg).cube(0).probe.empty());
}

TEST(RayCachePathMode, AutoLightsTheDiffuseLobeWhereTheSurroundingsAreFarAndNeverServes) {
  // Measured (docs/cache-report/path-cache.md): texels that serve reached uncached path
  // tracing's error later, the incoming-light probe sooner. Auto keeps the probe (and no texel
  // serves: no lookups) while what the object sees is far.
  LitSurroundings lit;
  const auto build = [&](ecs::Registry& r) { lit(r); };
  CacheSettings automatic;
  automatic.policy = CachePolicy::Auto;
  automatic.path_serve = true; // auto does not let texels serve, whatever it is told
  World cached, uncached;
  path_worlds(cached, uncached, automatic, [&](World& w, const CacheSettings& cs) {
    make_world(w, cs, 16, build, 48, vec3(0.0f, 0.3f, 4.0f), 2, mirror_material(0.5f));
  });
  Framebuffer a{1, 1}, b{1, 1};
  for (int k = 0; k < 4; ++k) {
    a = frame(cached);
    b = frame(uncached);
  }
  const FrameStats& last = cached.reg.resource<RenderJob>().last;
  EXPECT_EQ(last.cache.lookups, 0u);
  ASSERT_EQ(last.cache.cubes.size(), 1u);
  EXPECT_EQ(last.cache.cubes[0].mode, "irradiance");
  EXPECT_NE(last.cache.cubes[0].reason.find("incoming-light probe"), std::string::npos);
  EXPECT_TRUE(store_of(cached.reg).cube(0).lights_diffuse);
  EXPECT_GT(rmse(a, b), 0.0); // the lobe is lit by the probe, not sampled
}

TEST(RayCachePathMode, AutoTurnsTheProbeOffWhereTheSurroundingsAreNearAndRunsUncached) {
  // Inside a diffuse sphere of radius 6 (every leaving ray hits within 10 radii) the probe
  // would not stand for the mirror's every point: auto turns the cube off after a frame, and the
  // frames after are uncached ones, image and rays alike.
  const auto build = [](ecs::Registry& r) {
    test::add_mesh(r, test::primitive("sphere", 6.0f, vec3(1.0f), 48, 24), test::at(vec3(0.0f)),
                   diffuse(vec3(0.6f, 0.5f, 0.4f)));
    test::add_point_light(r, vec3(0, 3, 2), 40.0f);
  };
  CacheSettings automatic;
  automatic.policy = CachePolicy::Auto;
  World cached, uncached;
  path_worlds(cached, uncached, automatic, [&](World& w, const CacheSettings& cs) {
    make_world(w, cs, 16, build, 48, vec3(0.0f, 0.3f, 4.0f), 2, mirror_material(0.5f));
  });
  (void)frame(cached);
  (void)frame(uncached);
  const FrameStats& first = cached.reg.resource<RenderJob>().last;
  ASSERT_EQ(first.cache.cubes.size(), 1u);
  EXPECT_EQ(first.cache.cubes[0].mode, "off");
  EXPECT_NE(first.cache.cubes[0].reason.find("within 10 radii"), std::string::npos)
      << first.cache.cubes[0].reason;
  // The first frame had no probe yet, and the frames after are uncached ones: the images are
  // the same, and so are the rays.
  const Framebuffer a = frame(cached), b = frame(uncached);
  EXPECT_EQ(rmse(a, b), 0.0);
  EXPECT_EQ(cached.reg.resource<RenderJob>().last.rays.total(),
            uncached.reg.resource<RenderJob>().last.rays.total());
}

TEST(RayCachePathMode, AMoveOutdatesSamplesStillBeingAveraged) {
  // Texels that have samples but not yet enough to serve must lose them too when what they saw
  // moves: otherwise their mean would mix the old scene into the new one.
  MovingIntoView build;
  World w;
  make_world(w, path_cache(1000), 16, [&](ecs::Registry& r) { build(r); }, 48);
  path_mode(w);
  for (int k = 0; k < 3; ++k) (void)frame(w);
  ASSERT_EQ(store_of(w.reg).counts().valid, 0u);
  const cache::CubeView before = store_of(w.reg).cube(0);
  std::uint64_t pending = 0;
  for (const cache::ProbeTexel& p : before.probe) pending += p.samples > 0 ? 1 : 0;
  ASSERT_GT(pending, 100u);
  move(w.reg, build.c, vec3(1.2f, 0.0f, 2.5f));
  (void)frame(w);
  EXPECT_GT(store_of(w.reg).counts().invalidated, 0u);
}

} // namespace
} // namespace specula
