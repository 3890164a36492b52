// BART's Animated File Format (engine/scene/aff_loader.h) and the Kochanek–Bartels splines it
// brings (engine/scene/animation_sampling.h).
#include "specula/core/error.h"
#include "specula/scene/animation_sampling.h"
#include "specula/scene/components.h"
#include "specula/scene/json_scene.h"
#include "specula/scene/scene.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

namespace fs = std::filesystem;
using namespace specula;

namespace {

const fs::path kData = fs::path(SPECULA_TEST_DATA_DIR) / "aff";

ecs::Entity find_named(ecs::Registry& reg, const std::string& name) {
  ecs::Entity found = ecs::null_entity;
  reg.view<Name>().each([&](ecs::Entity e, const Name& n) {
    if (n.value == name) found = e;
  });
  return found;
}

/// Mesh entities whose parent is `parent` (null: at the root).
std::vector<ecs::Entity> meshes_under(ecs::Registry& reg, ecs::Entity parent) {
  std::vector<ecs::Entity> out;
  reg.view<Mesh>().each([&](ecs::Entity e, const Mesh&) {
    const Parent* p = reg.try_get<Parent>(e);
    if ((p ? p->entity : ecs::null_entity) == parent) out.push_back(e);
  });
  return out;
}

Keyframes<vec3> kb_track(std::vector<float> times, std::vector<vec3> values,
                         std::vector<vec3> tcb = {}) {
  Keyframes<vec3> k;
  k.interpolation = Interpolation::KochanekBartels;
  if (tcb.empty()) tcb.assign(times.size(), vec3(0.0f));
  k.times = std::move(times);
  k.values = std::move(values);
  k.tcb = std::move(tcb);
  return k;
}

} // namespace

TEST(Aff, ParsesEveryStaticCommandIntoComponents) {
  Scene scene = load_scene(kData / "basic.aff");
  ecs::Registry& reg = scene.registry;
  EXPECT_EQ(scene.settings.width, 64u);
  EXPECT_EQ(scene.settings.height, 48u);
  EXPECT_EQ(scene.settings.background, vec3(0.1f, 0.2f, 0.3f));
  EXPECT_EQ(scene.settings.anim_start, 0.0);
  EXPECT_EQ(scene.settings.anim_end, 2.0);
  EXPECT_EQ(scene.settings.anim_frames, 5u);

  const Camera cam = reg.get<Camera>(find_named(reg, "camera"));
  EXPECT_EQ(cam.position, dvec3(0, 2, 10));
  EXPECT_EQ(cam.look_at, dvec3(0));
  EXPECT_NEAR(cam.vertical_fov, glm::radians(40.0f), 1e-6f);
  EXPECT_FLOAT_EQ(cam.aspect, 64.0f / 48.0f);

  EXPECT_EQ(reg.count<Light>(), 2u);
  const ecs::Entity lamp = find_named(reg, "lamp");
  EXPECT_EQ(reg.get<Light>(lamp).color, vec3(1.0f, 0.5f, 0.25f));
  ASSERT_TRUE(reg.try_get<Animation>(lamp)); // `la` + `k lamp`: an animated light

  // The two `p` under material f merge into one mesh; `pp` (with normals) gets its own.
  const std::vector<ecs::Entity> root = meshes_under(reg, ecs::null_entity);
  std::size_t red = 0, green = 0;
  for (const ecs::Entity e : root) {
    const Material& m = reg.get<Material>(e);
    if (m.base_color == vec3(0.5f, 0.0f, 0.0f)) {
      ++red;
      EXPECT_EQ(reg.get<Mesh>(e).geometry->triangle_count(), 3u); // quad fan + triangle
      EXPECT_FLOAT_EQ(m.reflectivity, 0.25f);
      EXPECT_FLOAT_EQ(m.transmission, 0.5f);
      EXPECT_FLOAT_EQ(m.ior, 1.3f);
    } else if (m.base_color == vec3(0.0f, 0.5f, 0.0f)) {
      ++green;
      EXPECT_FLOAT_EQ(m.reflectivity, 0.4f); // largest specular component of `fm`
      const auto& geometry = *reg.get<Mesh>(e).geometry;
      if (geometry.triangle_count() == 1 && geometry.uvs.empty()) {
        ASSERT_EQ(geometry.normals.size(), 3u); // `pp` keeps its normals
      }
    }
    EXPECT_EQ(reg.get<Kinematics>(e).type, Kinematics::Type::Static);
  }
  EXPECT_EQ(red, 1u);
  EXPECT_EQ(green, 4u); // pp, sphere, tt, ttp: each its own vertex layout
  std::size_t textured = 0;
  for (const ecs::Entity e : root) {
    const Mesh& mesh = reg.get<Mesh>(e);
    const TriangleMesh& g = *mesh.geometry;
    if (g.uvs.empty() || mesh.source.kind == MeshSource::Kind::Primitive) continue;
    ++textured; // `tt` / `ttp`: texture coordinates kept (the texture is not)
    EXPECT_EQ(g.uvs[1], vec2(1, 0));
    EXPECT_EQ(g.normals.size(), g.positions[0].z == -2.0f ? 3u : 0u);
  }
  EXPECT_EQ(textured, 2u);

  // `xs`: a static node with its TRS, its `m` mesh beneath it.
  ecs::Entity xs = ecs::null_entity;
  reg.view<Name, Transform>().each([&](ecs::Entity e, const Name& n, const Transform&) {
    if (n.value.rfind("xs@", 0) == 0) xs = e;
  });
  ASSERT_NE(xs, ecs::null_entity);
  const Transform& xt = reg.get<Transform>(xs);
  EXPECT_EQ(xt.scale, vec3(2.0f));
  EXPECT_EQ(xt.translation, dvec3(1, 0, 0));
  EXPECT_NEAR(glm::angle(xt.rotation), glm::radians(90.0f), 1e-5f);
  ASSERT_EQ(meshes_under(reg, xs).size(), 1u);
  EXPECT_EQ(reg.get<Kinematics>(meshes_under(reg, xs)[0]).type, Kinematics::Type::Static);
}

TEST(Aff, CylindersAndConesBecomePrimitivesAlongTheirAxis) {
  const fs::path path = fs::temp_directory_path() / "specula_aff_cones.aff";
  std::ofstream(path) << "c 1 2 3 0.5 1 2 7 0.5\n" // cylinder along +Z, length 4
                         "c 0 0 0 2 0 -3 0 0\n"    // cone pointing down -Y
                         "c 5 0 0 0.5 5 0 2 1.5\n"; // truncated, wider end at the apex point
  Scene scene = load_scene(path);
  ecs::Registry& reg = scene.registry;
  int found = 0;
  reg.view<Mesh, Transform>().each([&](const Mesh& m, const Transform& t) {
    const vec3 axis = t.rotation * vec3(0, 1, 0); // the primitive's +Y in the scene
    if (m.source.primitive == "cylinder") {
      ++found;
      EXPECT_FLOAT_EQ(m.source.radius, 0.5f);
      EXPECT_FLOAT_EQ(m.source.height, 4.0f);
      EXPECT_EQ(t.translation, dvec3(1, 2, 5));
      EXPECT_NEAR(axis.z, 1.0f, 1e-6f);
    } else if (m.source.primitive == "cone" && m.source.top_radius == 0.0f) {
      ++found;
      EXPECT_FLOAT_EQ(m.source.radius, 2.0f);
      EXPECT_FLOAT_EQ(m.source.height, 3.0f);
      EXPECT_NEAR(axis.y, -1.0f, 1e-6f); // apex (primitive +Y) towards the file's apex
    } else if (m.source.primitive == "cone") {
      ++found;
      // The wide end is the base: the primitive's +Y (narrow top) points back to z = 0.
      EXPECT_FLOAT_EQ(m.source.radius, 1.5f);
      EXPECT_FLOAT_EQ(m.source.top_radius, 0.5f);
      EXPECT_FLOAT_EQ(m.source.height, 2.0f);
      EXPECT_EQ(t.translation, dvec3(5, 0, 1));
      EXPECT_NEAR(axis.z, -1.0f, 1e-6f);
      // Its world bounds: radius 1.5 across, 2 along z.
      const Aabb b = m.geometry->bounds();
      EXPECT_NEAR(b.max.x, 1.5f, 1e-5f);
      EXPECT_NEAR(b.max.y - b.min.y, 2.0f, 1e-5f);
    }
  });
  EXPECT_EQ(found, 3);
}

TEST(Aff, KeyframedTransformIsHierarchicalWithKochanekBartelsTracks) {
  Scene scene = load_scene(kData / "basic.aff");
  ecs::Registry& reg = scene.registry;
  const ecs::Entity car = find_named(reg, "car");
  ASSERT_NE(car, ecs::null_entity);
  const Animation& a = reg.get<Animation>(car);
  EXPECT_EQ(a.translation.interpolation, Interpolation::KochanekBartels);
  EXPECT_EQ(a.translation.times.size(), 5u);
  EXPECT_EQ(a.rotation.values.size(), 4u);
  EXPECT_TRUE(a.scale.empty());
  EXPECT_EQ(reg.get<Transform>(car).translation, dvec3(0)); // sampled at `a`'s start
  // The include (parts/wheel.aff → parts/hub.aff, each relative to its includer) put its
  // polygon under the car, which the keyframes make Hierarchical (settle_kinematics).
  const std::vector<ecs::Entity> parts = meshes_under(reg, car);
  ASSERT_EQ(parts.size(), 1u);
  EXPECT_EQ(reg.get<Mesh>(parts[0]).geometry->positions[0], vec3(0, 0, 1));
  EXPECT_EQ(reg.get<Kinematics>(parts[0]).type, Kinematics::Type::Hierarchical);
}

TEST(Aff, MorphingTrianglesAreFreeAndTheCameraMoves) {
  Scene scene = load_scene(kData / "museum.aff");
  ecs::Registry& reg = scene.registry;
  std::size_t morphs = 0;
  reg.view<Mesh, Animation>().each([&](ecs::Entity e, const Mesh& m, const Animation& a) {
    ++morphs;
    EXPECT_EQ(m.geometry->triangle_count(), 2u); // both tpa share their key times
    EXPECT_EQ(a.vertices.times, (std::vector<float>{0.0f, 1.0f}));
    EXPECT_EQ(a.vertices.values[1][0], vec3(0, 0, 1));
    EXPECT_EQ(reg.get<Kinematics>(e).type, Kinematics::Type::Free);
    // The normals morph with the triangles: a linear track of the file's normals per key, the
    // first key's in the geometry.
    EXPECT_EQ(a.normals.times, a.vertices.times);
    EXPECT_EQ(a.normals.interpolation, Interpolation::Linear);
    ASSERT_EQ(a.normals.values.size(), 2u);
    EXPECT_EQ(a.normals.values[1][0], vec3(0, 2, 2));
    EXPECT_EQ(a.normals.values[1][2], vec3(1, 0, 0));
    EXPECT_EQ(m.geometry->normals, a.normals.values[0]);
    // Halfway, each normal is the normalised blend of its keys' normals.
    std::vector<vec3> half;
    sample_normals(a.normals, 0.5f, half);
    ASSERT_EQ(half.size(), 6u);
    const vec3 expected = glm::normalize(vec3(0, 1, 1.5f));
    EXPECT_NEAR(glm::distance(half[0], expected), 0.0f, 1e-6f);
    EXPECT_NEAR(glm::length(half[2]), 1.0f, 1e-6f);
    EXPECT_NEAR(half[2].x, half[2].z, 1e-6f); // halfway between +Z and +X
  });
  EXPECT_EQ(morphs, 1u);
  const ecs::Entity cam = find_named(reg, "camera");
  const CameraPath& path = reg.get<CameraPath>(cam);
  ASSERT_EQ(path.keys.size(), 3u); // one per frame of `a 0 1 3`
  EXPECT_EQ(path.keys[0].position, dvec3(0, 0, 10));
  EXPECT_NEAR(path.keys[2].position.x, 5.0, 1e-5);
  // Turned 30° about +Y: looking down -Z rotated, at the `v` distance.
  const dvec3 dir = glm::normalize(path.keys[2].look_at - path.keys[2].position);
  EXPECT_NEAR(dir.x, -std::sin(glm::radians(30.0)), 1e-5);
  EXPECT_NEAR(dir.z, -std::cos(glm::radians(30.0)), 1e-5);
}

TEST(Aff, CameraRotationKeysRollTheView) {
  Scene scene = load_scene(kData / "roll.aff");
  ecs::Registry& reg = scene.registry;
  const ecs::Entity cam = find_named(reg, "camera");
  const CameraPath& path = reg.get<CameraPath>(cam);
  ASSERT_EQ(path.keys.size(), 3u); // one per frame of `a 0 1 3`
  // 0° at t = 0, 90° about the view axis (+Z, the camera looking down -Z) at t = 1: +Y turns to
  // -X; the view direction stays.
  EXPECT_NEAR(path.keys[0].up.y, 1.0f, 1e-5f);
  EXPECT_NEAR(path.keys[2].up.x, -1.0f, 1e-5f);
  EXPECT_NEAR(path.keys[2].up.y, 0.0f, 1e-5f);
  const dvec3 dir = glm::normalize(path.keys[2].look_at - path.keys[2].position);
  EXPECT_NEAR(dir.z, -1.0, 1e-6);
  // Halfway, the up has turned halfway (45°), still a unit vector.
  const CameraPath::Key half = sample(path, 0.5f);
  EXPECT_NEAR(half.up.x, -std::sqrt(0.5f), 1e-5f);
  EXPECT_NEAR(half.up.y, std::sqrt(0.5f), 1e-5f);
  // And it survives a save and a load.
  Scene back = parse_json_scene(write_json_scene(scene), "round trip", kData);
  EXPECT_EQ(back.registry.get<CameraPath>(find_named(back.registry, "camera")).keys, path.keys);
}

TEST(Aff, SavesToJsonAndLoadsBackEqual) {
  Scene scene = load_scene(kData / "basic.aff");
  const std::string text = write_json_scene(scene);
  Scene back = parse_json_scene(text, "round trip", kData);
  const ecs::Entity a = find_named(scene.registry, "car");
  const ecs::Entity b = find_named(back.registry, "car");
  ASSERT_NE(b, ecs::null_entity);
  EXPECT_EQ(scene.registry.get<Animation>(a), back.registry.get<Animation>(b));
  // The lamp's visibility keys (off from 0.5 s, on again from 1.5 s) survive the round trip.
  const Animation& lamp = scene.registry.get<Animation>(find_named(scene.registry, "lamp"));
  EXPECT_EQ(lamp.visibility.times, (std::vector<float>{0.5f, 1.5f}));
  EXPECT_EQ(lamp.visibility.visible, (std::vector<std::uint8_t>{0, 1}));
  EXPECT_EQ(back.registry.get<Animation>(find_named(back.registry, "lamp")), lamp);
  EXPECT_EQ(back.registry.get<Animation>(b).rotation.tcb.size(), 4u);
  EXPECT_EQ(back.settings, scene.settings); // `a` included
  EXPECT_EQ(back.settings.anim_frames, 5u);
  const SceneSummary sa = summarize(scene), sb = summarize(back);
  EXPECT_EQ(sb.mesh_entities, sa.mesh_entities);
  EXPECT_EQ(sb.triangles, sa.triangles);
  EXPECT_EQ(sb.materials, sa.materials);
  EXPECT_EQ(sb.lights, sa.lights);
  EXPECT_EQ(sb.animated, sa.animated);
}

TEST(KochanekBartels, PassesThroughEveryInnerKeyAndClampsToThem) {
  const auto k =
      kb_track({0, 1, 2.5f, 3, 5}, {vec3(0), vec3(1, 2, 3), vec3(-4, 0, 1), vec3(2, 2, 2), vec3(9)},
               {vec3(0), vec3(0.3f, -0.2f, 0.5f), vec3(-0.5f, 0.4f, 0.1f), vec3(0.2f), vec3(0)});
  for (std::size_t i = 1; i + 1 < k.times.size(); ++i)
    EXPECT_EQ(sample(k, k.times[i]), k.values[i]);
  EXPECT_EQ(sample(k, -10.0f), k.values[1]); // first and last keys only shape the ends
  EXPECT_EQ(sample(k, 10.0f), k.values[3]);
}

TEST(KochanekBartels, ALoopingAnimationWrapsAtTheLastInnerKey) {
  // The last key only shapes the end tangent: the track stops changing at times[n-2] (3 here),
  // and a looping animation must wrap there, not hold the end value until the last key (5).
  Animation a;
  a.translation.interpolation = Interpolation::KochanekBartels;
  a.translation.times = {0, 1, 2.5f, 3, 5};
  a.translation.values.assign(5, dvec3(0));
  a.translation.tcb.assign(5, vec3(0));
  EXPECT_FLOAT_EQ(a.duration(), 3.0f);
  a.scale.times = {0, 4};
  a.scale.values = {vec3(1), vec3(2)};
  EXPECT_FLOAT_EQ(a.duration(), 4.0f); // a linear track still ends at its last key
}

TEST(KochanekBartels, ZeroTcbOnUniformKeysIsCatmullRom) {
  const std::vector<vec3> p = {vec3(0, 0, 0), vec3(1, 2, 0), vec3(3, 1, -1), vec3(4, 5, 2)};
  const auto k = kb_track({0, 1, 2, 3}, p);
  for (float u = 0.0f; u <= 1.0f; u += 0.125f) {
    // Catmull–Rom in its matrix form (an independent formula).
    const vec3 cr = 0.5f * (2.0f * p[1] + (-p[0] + p[2]) * u +
                            (2.0f * p[0] - 5.0f * p[1] + 4.0f * p[2] - p[3]) * u * u +
                            (-p[0] + 3.0f * p[1] - 3.0f * p[2] + p[3]) * u * u * u);
    const vec3 kb = sample(k, 1.0f + u);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(kb[c], cr[c], 1e-5f) << "u=" << u;
  }
}

TEST(KochanekBartels, UnevenKeysKeepVelocityContinuousAtTheSecantSlope) {
  // The time adjustment (BART's adj0/adj1) makes the velocity at a key, from either side,
  // (P[i+1] - P[i-1]) / (t[i+1] - t[i-1]) when t = c = b = 0, however unevenly keys are spaced.
  const std::vector<float> t = {0, 1, 3, 3.5f, 6, 7};
  const std::vector<vec3> p = {vec3(0),       vec3(1, 2, 0),  vec3(3, 1, -1),
                               vec3(4, 5, 2), vec3(-2, 0, 1), vec3(0, 1, 0)};
  const auto f = kb_track(t, p);
  Keyframes<dvec3> k; // double values: finite differences need the precision
  k.interpolation = f.interpolation;
  k.times = f.times;
  k.tcb = f.tcb;
  for (const vec3& v : p) k.values.push_back(dvec3(v));
  for (std::size_t i = 2; i <= 3; ++i) {
    const float ahead = t[i] + 1e-4f, behind = t[i] - 1e-4f; // steps as float times hold them
    const dvec3 secant = dvec3(p[i + 1] - p[i - 1]) / double(t[i + 1] - t[i - 1]);
    const dvec3 right = (sample(k, ahead) - sample(k, t[i])) / (double(ahead) - t[i]);
    const dvec3 left = (sample(k, t[i]) - sample(k, behind)) / (double(t[i]) - behind);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(right[c], secant[c], 0.01) << "key " << i;
      EXPECT_NEAR(left[c], secant[c], 0.01) << "key " << i;
    }
  }
}

TEST(KochanekBartels, TensionOneGivesZeroTangents) {
  const std::vector<vec3> p = {vec3(5, -3, 0), vec3(1, 2, 0), vec3(3, 1, -1), vec3(-4, 5, 2)};
  const auto k = kb_track({0, 1, 2, 3}, p, std::vector<vec3>(4, vec3(1, 0, 0)));
  for (float u = 0.0f; u <= 1.0f; u += 0.125f) {
    const vec3 expect = p[1] + (3.0f * u * u - 2.0f * u * u * u) * (p[2] - p[1]);
    const vec3 kb = sample(k, 1.0f + u);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(kb[c], expect[c], 1e-5f) << "u=" << u;
  }
}

TEST(KochanekBartels, BiasAndContinuityChooseTheSideOfTheTangent) {
  // Incoming leg along +X, outgoing leg along +Y: the one-sided tangents are told apart.
  const std::vector<vec3> p = {vec3(-1, 0, 0), vec3(0, 0, 0), vec3(0, 1, 0), vec3(0, 2, 0)};
  const float h = 1e-3f;
  const auto start_slope = [&](vec3 tcb_at_1) {
    const auto k = kb_track({0, 1, 2, 3}, p, {vec3(0), tcb_at_1, vec3(0), vec3(0)});
    return (sample(k, 1.0f + h) - sample(k, 1.0f)) / h;
  };
  // Bias +1: overshoot, the outgoing tangent is the incoming leg P1 - P0 (Kochanek–Bartels 1984).
  const vec3 b = start_slope(vec3(0, 0, 1));
  EXPECT_NEAR(b.x, 1.0f, 0.01f);
  EXPECT_NEAR(b.y, 0.0f, 0.01f);
  // Bias −1: undershoot, the outgoing leg P2 - P1.
  const vec3 u = start_slope(vec3(0, 0, -1));
  EXPECT_NEAR(u.x, 0.0f, 0.01f);
  EXPECT_NEAR(u.y, 1.0f, 0.01f);
  // Continuity −1: the outgoing (source) tangent is the outgoing leg, a corner at the key.
  const vec3 c = start_slope(vec3(0, -1, 0));
  EXPECT_NEAR(c.x, 0.0f, 0.01f);
  EXPECT_NEAR(c.y, 1.0f, 0.01f);
}

TEST(KochanekBartels, RotationStaysUnitAndHitsTheKeys) {
  Keyframes<quat> k;
  k.interpolation = Interpolation::KochanekBartels;
  k.times = {0, 1, 2, 3, 4};
  k.values = {glm::angleAxis(0.3f, vec3(1, 0, 0)), glm::angleAxis(1.0f, vec3(0, 1, 0)),
              -glm::angleAxis(2.5f, glm::normalize(vec3(1, 1, 0))), // other hemisphere
              glm::angleAxis(-1.0f, vec3(0, 0, 1)), glm::angleAxis(0.5f, vec3(0, 1, 0))};
  k.tcb = {vec3(0), vec3(0.2f, 0.1f, -0.3f), vec3(0), vec3(-0.4f, 0.5f, 0.2f), vec3(0)};
  Animation a;
  a.rotation = k;
  validate_animation(a, 0, "test", "a");
  for (float t = 1.0f; t <= 3.0f; t += 0.01f)
    EXPECT_NEAR(glm::length(sample(k, t)), 1.0f, 1e-5f) << t;
  for (std::size_t i = 1; i <= 3; ++i)
    EXPECT_NEAR(std::abs(glm::dot(sample(k, k.times[i]), k.values[i])), 1.0f, 1e-5f) << i;
}

TEST(KochanekBartels, ValidationRejectsShortTracksAndBadTcb) {
  Animation a;
  a.translation.interpolation = Interpolation::KochanekBartels;
  a.translation.times = {0, 1, 2};
  a.translation.values = {dvec3(0), dvec3(1), dvec3(2)};
  a.translation.tcb = {vec3(0), vec3(0), vec3(0)};
  EXPECT_THROW(validate_animation(a, 0, "t", "a"), Error);
  a.translation.times.push_back(3);
  a.translation.values.push_back(dvec3(3));
  EXPECT_THROW(validate_animation(a, 0, "t", "a"), Error); // 3 tcb for 4 keys
  a.translation.tcb.push_back(vec3(std::nanf("")));
  EXPECT_THROW(validate_animation(a, 0, "t", "a"), Error);
  a.translation.tcb.back() = vec3(0, 1.5f, 0); // outside Kochanek–Bartels' [-1, 1]
  EXPECT_THROW(validate_animation(a, 0, "t", "a"), Error);
  a.translation.tcb.back() = vec3(0);
  EXPECT_NO_THROW(validate_animation(a, 0, "t", "a"));
}

struct BadAff {
  const char* name;
  const char* text;
  int line;
  const char* message;
};

class AffBadFile : public ::testing::TestWithParam<BadAff> {};

TEST_P(AffBadFile, ErrorNamesFileLineAndProblem) {
  const BadAff& c = GetParam();
  const fs::path dir = fs::temp_directory_path() / "specula_aff_bad";
  fs::create_directories(dir);
  const fs::path path = dir / (std::string(c.name) + ".aff");
  std::ofstream(path) << c.text;
  try {
    (void)load_scene(path);
    FAIL() << "no error for " << c.name;
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(path.filename().string() + ":" + std::to_string(c.line) + ":"),
              std::string::npos)
        << what;
    EXPECT_NE(what.find(c.message), std::string::npos) << what;
  }
}

INSTANTIATE_TEST_SUITE_P(
    Cases, AffBadFile,
    ::testing::Values(
        BadAff{"unknown", "b 0 0 0\nzz 1 2\n", 2, "unknown command 'zz'"},
        BadAff{"missing", "b 0 0\n", 1, "unexpected end of file"},
        BadAff{"nonnumeric", "b 0 x 0\n", 1, "expected a number"},
        BadAff{"nan", "\nb 0 nan 0\n", 2, "not finite"},
        BadAff{"overflow", "b 0 1e999 0\n", 1, "out of range"},
        BadAff{"short_polygon", "p 4\n0 0 0\n1 0 0\n0 1 0\nb 0 0 0\n", 5, "expected a number"},
        BadAff{"absurd_count", "p 99999999999\n0 0 0\n", 1, "limit"},
        BadAff{"count_past_file", "p 1000000\n0 0 0\n", 1, "rest of the file"},
        BadAff{"two_vertices", "p 2\n0 0 0\n1 0 0\n", 1, "at least 3"},
        BadAff{"mesh_index", "m vertices 3 0 0 0 1 0 0 0 1 0\ntriangles 1\n0 1 3\n", 3,
               "out of range"},
        BadAff{"key_order",
               "x n {\n}\nk n {\ntransl 4\n0 0 0 0 0 0 0\n1 0 0 0 0 0 0\n"
               "1 0 0 0 0 0 0\n2 0 0 0 0 0 0\n}\n",
               7, "strictly increasing"},
        BadAff{"few_keys",
               "x n {\n}\nk n {\ntransl 3\n0 0 0 0 0 0 0\n1 0 0 0 0 0 0\n2 0 0 0 0 0 0\n}\n", 4,
               "at least 4"},
        BadAff{"unknown_name", "k ghost {\n}\n", 1, "ghost"},
        BadAff{"unbalanced", "x n {\n}\n}\n", 3, "without an open transform"},
        BadAff{"unclosed", "\nxs 1 1 1 0 1 0 0 0 0 0 {\n", 2, "never closed"},
        BadAff{"flat_cone", "\nc 0 0 0 1 0 0 0 1\n", 2, "coincide"},
        BadAff{"missing_include", "\ni 0 nowhere.aff\n", 2, "not found"},
        BadAff{"far_view",
               "v\nfrom 0 0 1e30\nat 0 0 0\nup 0 1 0\nangle 40\nhither 1\nresolution 4 4\n", 1,
               "outside"},
        BadAff{"wild_tension",
               "x n {\n}\nk n {\nscale 4\n0 1 1 1 0 0 0\n1 1 1 1 0 0 0\n2 1 1 1 9 0 0\n"
               "3 1 1 1 0 0 0\n}\n",
               3, "[-1, 1]"},
        BadAff{"zero_tpa_normal", "tpa 1\n0\n0 0 0 0 0 1\n1 0 0 0 0 0\n0 1 0 0 0 1\n", 4,
               "zero length"},
        BadAff{"bad_view",
               "v\nfrom 0 0 0\nat 0 0 1\nup 0 1 0\nangle 200\nhither 1\n"
               "resolution 4 4\n",
               1, "angle"}),
    [](const ::testing::TestParamInfo<BadAff>& p) { return std::string(p.param.name); });

TEST(Aff, KeyframesAnimateEveryTransformOfTheirName) {
  // BART finds animations by name: a part included twice moves twice.
  const fs::path path = fs::temp_directory_path() / "specula_aff_twice.aff";
  std::ofstream(path) << "x wheel {\np 3 0 0 0 1 0 0 0 1 0\n}\n"
                         "xs 1 1 1 0 1 0 0 5 0 0 {\nx wheel {\np 3 0 0 0 1 0 0 0 1 0\n}\n}\n"
                         "k wheel {\nscale 4\n0 1 1 1 0 0 0\n1 1 1 1 0 0 0\n2 2 2 2 0 0 0\n"
                         "3 2 2 2 0 0 0\n}\n";
  Scene scene = load_scene(path);
  std::size_t animated = 0;
  scene.registry.view<Name, Animation>().each([&](const Name& n, const Animation& a) {
    EXPECT_EQ(n.value, "wheel");
    EXPECT_EQ(a.scale.interpolation, Interpolation::KochanekBartels);
    ++animated;
  });
  EXPECT_EQ(animated, 2u);
  scene.registry.view<Mesh, Kinematics>().each(
      [](const Mesh&, const Kinematics& k) { EXPECT_EQ(k.type, Kinematics::Type::Hierarchical); });
}

TEST(Aff, IncludesAboveTheDetailLevelAreSkipped) {
  const fs::path dir = fs::temp_directory_path() / "specula_aff_detail";
  fs::create_directories(dir / "sub");
  std::ofstream(dir / "sub" / "coarse.aff") << "p 3 0 0 0 1 0 0 0 1 0\n";
  std::ofstream(dir / "sub" / "fine.aff") << "p 3 0 0 0 1 0 0 0 1 0\np 3 0 0 0 1 0 0 0 1 0\n";
  std::ofstream(dir / "scene.aff") << "d 1\ni 1 sub/coarse.aff\ni 2 sub/fine.aff\n";
  Scene scene = load_scene(dir / "scene.aff");
  EXPECT_EQ(summarize(scene).triangles, 1u); // detail 2 > level 1: fine.aff left out
}

TEST(Aff, IncludeCycleIsAnError) {
  try {
    (void)load_scene(kData / "cycle_a.aff");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("cycle"), std::string::npos) << e.what();
  }
}

TEST(Aff, HundredThousandPolygonsMergeIntoOneMesh) {
  const fs::path path = fs::temp_directory_path() / "specula_aff_big.aff";
  {
    std::ofstream out(path);
    out << "f 1 1 1 1 0 0 0 1\n";
    for (int i = 0; i < 50'000; ++i) {
      const int x = i % 250, y = i / 250;
      out << "p 4\n"
          << x << " " << y << " 0\n"
          << x + 1 << " " << y << " 0\n"
          << x + 1 << " " << y + 1 << " 0\n"
          << x << " " << y + 1 << " 0\n";
    }
  }
  Scene scene = load_scene(path);
  const SceneSummary s = summarize(scene);
  EXPECT_EQ(s.triangles, 100'000u);
  EXPECT_EQ(s.mesh_entities, 1u);
}
