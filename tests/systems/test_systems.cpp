// Headless system tests: build a world, tick the schedule, assert on components.

#include "specula/core/error.h"
#include "specula/render/scene_layer.h"
#include "specula/scene/kinematics_rules.h"
#include "specula/scene/components.h"
#include "specula/systems/animation_system.h"
#include "specula/systems/schedule.h"
#include "specula/systems/transform_system.h"

#include <glm/gtc/matrix_transform.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <numbers>
#include <random>

namespace specula {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;

void expect_near(const mat4& a, const mat4& b, float tol = 1e-4f) {
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r)
      EXPECT_NEAR(a[c][r], b[c][r], tol) << "column " << c << " row " << r;
}

/// A rotation track about `axis` turning a full circle in `period` seconds (5 keys, linear).
Keyframes<quat> spin(const vec3& axis, float period) {
  Keyframes<quat> track;
  for (int k = 0; k <= 4; ++k) {
    track.times.push_back(period * float(k) / 4.0f);
    track.values.push_back(glm::angleAxis(2.0f * kPi * float(k) / 4.0f, axis));
  }
  return track;
}

struct Arm {
  ecs::Entity base, elbow, hand, bystander;
};

/// Three links: the base spins about +Y, the elbow (1 unit along +X from the base) spins about
/// +Z, the hand sits 0.5 along +X from the elbow without animation of its own. A static
/// bystander never moves.
Arm make_arm(ecs::Registry& reg, float base_period, float elbow_period) {
  Arm arm;
  arm.base = reg.create();
  reg.emplace<Transform>(arm.base);
  reg.emplace<Kinematics>(arm.base, Kinematics{Kinematics::Type::Hierarchical});
  Animation base_anim;
  base_anim.rotation = spin(vec3(0, 1, 0), base_period);
  reg.emplace<Animation>(arm.base, base_anim);

  arm.elbow = reg.create();
  Transform elbow_t;
  elbow_t.translation = vec3(1, 0, 0);
  reg.emplace<Transform>(arm.elbow, elbow_t);
  reg.emplace<Parent>(arm.elbow, Parent{arm.base});
  reg.emplace<Kinematics>(arm.elbow, Kinematics{Kinematics::Type::Hierarchical});
  Animation elbow_anim;
  elbow_anim.rotation = spin(vec3(0, 0, 1), elbow_period);
  reg.emplace<Animation>(arm.elbow, elbow_anim);

  arm.hand = reg.create();
  Transform hand_t;
  hand_t.translation = vec3(0.5f, 0, 0);
  reg.emplace<Transform>(arm.hand, hand_t);
  reg.emplace<Parent>(arm.hand, Parent{arm.elbow});
  reg.emplace<Kinematics>(arm.hand, Kinematics{Kinematics::Type::Hierarchical});

  arm.bystander = reg.create();
  Transform by_t;
  by_t.translation = vec3(5, 0, 0);
  reg.emplace<Transform>(arm.bystander, by_t);
  reg.emplace<Kinematics>(arm.bystander);
  return arm;
}

TEST(Systems, ThreeLinkArmHasExpectedWorldTransformsAfterNTicks) {
  ecs::Registry reg;
  const Arm arm = make_arm(reg, 4.0f, 2.0f);
  Schedule schedule;
  const double dt = 1.0 / 60.0;
  const int ticks = 37;
  for (int i = 0; i < ticks; ++i) schedule.tick(reg, dt);

  // Expected from first principles: angles at t, composed base * elbow * hand.
  const float t = float(ticks * dt);
  const float base_angle = 2.0f * kPi * t / 4.0f;
  const float elbow_angle = 2.0f * kPi * t / 2.0f;
  const mat4 world_from_base = glm::rotate(mat4(1.0f), base_angle, vec3(0, 1, 0));
  const mat4 base_from_elbow =
      glm::rotate(glm::translate(mat4(1.0f), vec3(1, 0, 0)), elbow_angle, vec3(0, 0, 1));
  const mat4 elbow_from_hand = glm::translate(mat4(1.0f), vec3(0.5f, 0, 0));
  // Linear slerp between quarter-turn keys is exact rotation at constant angular speed.
  expect_near(reg.get<WorldTransform>(arm.base).world_from_object, world_from_base);
  expect_near(reg.get<WorldTransform>(arm.elbow).world_from_object,
              world_from_base * base_from_elbow);
  expect_near(reg.get<WorldTransform>(arm.hand).world_from_object,
              world_from_base * base_from_elbow * elbow_from_hand);
  // The hand's position has the closed form R_y(a) (x_e + R_z(b) (0.5, 0, 0)).
  const vec3 hand_base =
      vec3(1, 0, 0) + 0.5f * vec3(std::cos(elbow_angle), std::sin(elbow_angle), 0);
  const vec3 hand_world(hand_base.x * std::cos(base_angle) + hand_base.z * std::sin(base_angle),
                        hand_base.y,
                        -hand_base.x * std::sin(base_angle) + hand_base.z * std::cos(base_angle));
  const vec3 got = vec3(reg.get<WorldTransform>(arm.hand).world_from_object[3]);
  EXPECT_NEAR(got.x, hand_world.x, 1e-4f);
  EXPECT_NEAR(got.y, hand_world.y, 1e-4f);
  EXPECT_NEAR(got.z, hand_world.z, 1e-4f);
  expect_near(reg.get<WorldTransform>(arm.bystander).world_from_object,
              glm::translate(mat4(1.0f), vec3(5, 0, 0)));
}

TEST(Systems, ExactlyTheMovedEntitiesAreFlagged) {
  ecs::Registry reg;
  const Arm arm = make_arm(reg, 4.0f, 2.0f);
  // Stop the base: only the elbow animates, so base and bystander must not be flagged, while the
  // hand (child of the elbow) must be.
  reg.remove<Animation>(arm.base);
  Schedule schedule;
  schedule.tick(reg, 0.1); // first tick: every entity is new
  for (const ecs::Entity e : {arm.base, arm.elbow, arm.hand, arm.bystander})
    EXPECT_TRUE(reg.get<WorldTransform>(e).moved);
  for (int i = 0; i < 5; ++i) {
    const FrameContext ctx = schedule.tick(reg, 0.1);
    EXPECT_FALSE(reg.get<WorldTransform>(arm.base).moved) << "tick " << ctx.tick;
    EXPECT_TRUE(reg.get<WorldTransform>(arm.elbow).moved) << "tick " << ctx.tick;
    EXPECT_TRUE(reg.get<WorldTransform>(arm.hand).moved) << "tick " << ctx.tick;
    EXPECT_FALSE(reg.get<WorldTransform>(arm.bystander).moved) << "tick " << ctx.tick;
    EXPECT_EQ(reg.get<WorldTransform>(arm.hand).moved_tick, ctx.tick);
  }
  std::size_t flagged = 0;
  reg.view<WorldTransform>().each([&](const WorldTransform& wt) { flagged += wt.moved ? 1 : 0; });
  EXPECT_EQ(flagged, 2u);
}

TEST(Systems, NothingIsFlaggedOnceAnimationsEnd) {
  ecs::Registry reg;
  const Arm arm = make_arm(reg, 4.0f, 2.0f);
  reg.get<Animation>(arm.base).loop = false;
  reg.get<Animation>(arm.elbow).loop = false;
  Schedule schedule;
  for (int i = 0; i < 60; ++i) schedule.tick(reg, 0.1); // 6 s: past both durations
  schedule.tick(reg, 0.1);
  reg.view<WorldTransform>().each([&](ecs::Entity e, const WorldTransform& wt) {
    EXPECT_FALSE(wt.moved) << "entity " << e.index;
  });
}

TEST(Systems, AFreeEntityMovedByHandIsFlaggedOnlyOnThatTick) {
  ecs::Registry reg;
  const Arm arm = make_arm(reg, 4.0f, 2.0f);
  reg.remove<Animation>(arm.base);
  reg.remove<Animation>(arm.elbow);
  Schedule schedule;
  schedule.tick(reg, 0.1);
  reg.get<Transform>(arm.bystander).translation.y = 2.0f;
  schedule.tick(reg, 0.1);
  EXPECT_TRUE(reg.get<WorldTransform>(arm.bystander).moved);
  EXPECT_FALSE(reg.get<WorldTransform>(arm.base).moved);
  EXPECT_FALSE(reg.get<WorldTransform>(arm.hand).moved);
  schedule.tick(reg, 0.1);
  EXPECT_FALSE(reg.get<WorldTransform>(arm.bystander).moved);
}

TEST(Systems, ReparentingMovesTheChildAndItsSubtree) {
  ecs::Registry reg;
  const Arm arm = make_arm(reg, 4.0f, 2.0f);
  reg.remove<Animation>(arm.base);
  reg.remove<Animation>(arm.elbow);
  Schedule schedule;
  schedule.tick(reg, 0.1);
  reg.get<Parent>(arm.elbow).entity = arm.bystander;
  schedule.tick(reg, 0.1);
  EXPECT_TRUE(reg.get<WorldTransform>(arm.elbow).moved);
  EXPECT_TRUE(reg.get<WorldTransform>(arm.hand).moved);
  EXPECT_FALSE(reg.get<WorldTransform>(arm.base).moved);
  EXPECT_NEAR(reg.get<WorldTransform>(arm.hand).world_from_object[3].x, 6.5f, 1e-5f);
}

TEST(Systems, ParentCycleIsAnErrorNotAHang) {
  ecs::Registry reg;
  const ecs::Entity a = reg.create();
  const ecs::Entity b = reg.create();
  reg.emplace<Transform>(a);
  reg.emplace<Transform>(b);
  reg.emplace<Parent>(a, Parent{b});
  reg.emplace<Parent>(b, Parent{a});
  Schedule schedule;
  EXPECT_THROW(schedule.tick(reg, 0.1), Error);
}

TEST(Systems, DestroyedParentIsAnError) {
  ecs::Registry reg;
  const ecs::Entity parent = reg.create();
  const ecs::Entity child = reg.create();
  reg.emplace<Transform>(parent);
  reg.emplace<Transform>(child);
  reg.emplace<Parent>(child, Parent{parent});
  reg.destroy(parent);
  Schedule schedule;
  try {
    schedule.tick(reg, 0.1);
    FAIL() << "expected specula::Error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("no longer exists"), std::string::npos) << e.what();
  }
}

TEST(Systems, DeepHierarchyIsHandledWithoutRecursion) {
  // 100k links: a recursive propagation would overflow the stack.
  ecs::Registry reg;
  constexpr int kDepth = 100000;
  ecs::Entity prev = ecs::null_entity;
  for (int i = 0; i < kDepth; ++i) {
    const ecs::Entity e = reg.create();
    Transform t;
    t.translation = vec3(1, 0, 0);
    reg.emplace<Transform>(e, t);
    if (!prev.is_null()) reg.emplace<Parent>(e, Parent{prev});
    prev = e;
  }
  Schedule schedule;
  schedule.tick(reg, 0.0);
  EXPECT_FLOAT_EQ(reg.get<WorldTransform>(prev).world_from_object[3].x, float(kDepth));
}

TEST(Systems, ChildrenCreatedBeforeParentsStillGetParentFirstOrder) {
  // Slot order is child first; the result must not depend on it.
  ecs::Registry reg;
  std::mt19937 rng(1234);
  std::vector<ecs::Entity> chain(50);
  for (auto& e : chain) e = reg.create();
  std::shuffle(chain.begin(), chain.end(), rng);
  for (std::size_t i = 0; i < chain.size(); ++i) {
    Transform t;
    t.translation = vec3(0, 1, 0);
    t.scale = vec3(1.0f);
    reg.emplace<Transform>(chain[i], t);
    if (i > 0) reg.emplace<Parent>(chain[i], Parent{chain[i - 1]});
  }
  Schedule schedule;
  schedule.tick(reg, 0.0);
  for (std::size_t i = 0; i < chain.size(); ++i)
    EXPECT_FLOAT_EQ(reg.get<WorldTransform>(chain[i]).world_from_object[3].y, float(i + 1));
}

/// A shared mesh of one triangle in the z = 0 plane, for the vertex- and normal-track tests.
std::shared_ptr<TriangleMesh> one_triangle() {
  auto mesh = std::make_shared<TriangleMesh>();
  mesh->positions = {vec3(0, 0, 0), vec3(1, 0, 0), vec3(0, 1, 0)};
  mesh->triangles = {uvec3(0, 1, 2)};
  return mesh;
}

TEST(Systems, VertexAnimationDeformsTheEntitysPositionsNotTheSharedMesh) {
  ecs::Registry reg;
  const std::shared_ptr<TriangleMesh> shared = one_triangle();
  const ecs::Entity a = reg.create();
  const ecs::Entity b = reg.create();
  for (const ecs::Entity e : {a, b}) {
    reg.emplace<Transform>(e);
    reg.emplace<Mesh>(e, Mesh{shared, {}, {}, 0});
  }
  Animation anim;
  anim.loop = false;
  anim.vertices.times = {0.0f, 1.0f};
  anim.vertices.values = {shared->positions, {vec3(0, 0, 2), vec3(1, 0, 2), vec3(0, 1, 2)}};
  reg.emplace<Animation>(a, anim);
  Schedule schedule;
  const FrameContext ctx = schedule.tick(reg, 0.25);
  const Mesh& mesh_a = reg.get<Mesh>(a);
  ASSERT_EQ(mesh_a.positions().size(), 3u);
  for (const vec3& p : mesh_a.positions()) EXPECT_NEAR(p.z, 0.5f, 1e-6f);
  EXPECT_EQ(mesh_a.deformed_tick, ctx.tick);
  for (const vec3& p : reg.get<Mesh>(b).positions()) EXPECT_EQ(p.z, 0.0f);
  for (const vec3& p : shared->positions) EXPECT_EQ(p.z, 0.0f);
}

TEST(Systems, NormalTracksGiveUnitNormalsAndOppositeKeysNeverANan) {
  ecs::Registry reg;
  const std::shared_ptr<TriangleMesh> shared = one_triangle();
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e);
  reg.emplace<Mesh>(e, Mesh{shared, {}, {}, 0});
  Animation anim;
  anim.loop = false;
  anim.vertices.times = {0.0f, 1.0f};
  anim.vertices.values = {shared->positions, shared->positions};
  // Vertex 0 turns from +Z to +X with keys of length 2 and 1; vertex 1 flips from +Z to -Z
  // (the blend passes through zero halfway); vertex 2 holds still.
  anim.normals.times = {0.0f, 1.0f};
  anim.normals.values = {{vec3(0, 0, 2), vec3(0, 0, 1), vec3(0, 1, 0)},
                         {vec3(1, 0, 0), vec3(0, 0, -1), vec3(0, 1, 0)}};
  reg.emplace<Animation>(e, anim);
  Schedule schedule;
  const auto normals_at = [&](double dt) {
    schedule.tick(reg, dt);
    return reg.get<Mesh>(e).deformed_normals;
  };
  std::vector<vec3> n = normals_at(0.25); // t = 0.25
  ASSERT_EQ(n.size(), 3u);
  // The keys blend as given, then normalise: (0.25, 0, 1.5) for vertex 0.
  EXPECT_LT(glm::distance(n[0], glm::normalize(vec3(0.25f, 0, 1.5f))), 1e-6f);
  EXPECT_EQ(n[1], vec3(0, 0, 1));
  EXPECT_EQ(n[2], vec3(0, 1, 0));
  n = normals_at(0.25); // t = 0.5: vertex 1's blend is zero, so the nearer key's (the later one)
  EXPECT_EQ(n[1], vec3(0, 0, -1));
  for (const vec3& v : n) EXPECT_NEAR(glm::length(v), 1.0f, 1e-6f);
  n = normals_at(0.6); // past the last key: the last key's normals, normalised
  EXPECT_EQ(n[0], vec3(1, 0, 0));
  EXPECT_EQ(n[1], vec3(0, 0, -1));
  // Without a normal track the deformed mesh has none (face normals in shading).
  reg.get<Animation>(e).normals = {};
  reg.get<Animation>(e).time = 0.0f;
  EXPECT_TRUE(normals_at(0.1).empty());
}

TEST(Systems, StepInterpolationHoldsThePreviousKey) {
  ecs::Registry reg;
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e);
  Animation anim;
  anim.translation.interpolation = Interpolation::Step;
  anim.translation.times = {0.0f, 1.0f, 2.0f};
  anim.translation.values = {vec3(0), vec3(10, 0, 0), vec3(20, 0, 0)};
  reg.emplace<Animation>(e, anim);
  Schedule schedule;
  schedule.tick(reg, 0.9);
  EXPECT_EQ(reg.get<Transform>(e).translation.x, 0.0f);
  schedule.tick(reg, 0.2);
  EXPECT_EQ(reg.get<Transform>(e).translation.x, 10.0f);
}

TEST(Systems, LoopingAnimationWrapsToItsDuration) {
  ecs::Registry reg;
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e);
  Animation anim;
  anim.translation.times = {0.0f, 2.0f};
  anim.translation.values = {vec3(0), vec3(2, 0, 0)};
  reg.emplace<Animation>(e, anim);
  Schedule schedule;
  for (int i = 0; i < 5; ++i) schedule.tick(reg, 1.0); // t = 5 wraps to 1
  EXPECT_NEAR(reg.get<Transform>(e).translation.x, 1.0f, 1e-5f);
}

TEST(Systems, CameraFollowsItsPath) {
  ecs::Registry reg;
  const ecs::Entity e = reg.create();
  reg.emplace<Camera>(e);
  CameraPath path;
  path.loop = false;
  // The second key rolls the camera 90° about its view axis.
  path.keys = {{0.0f, vec3(0, 0, 10), vec3(0), vec3(0, 1, 0)},
               {2.0f, vec3(10, 0, 10), vec3(10, 0, 0), vec3(-1, 0, 0)}};
  reg.emplace<CameraPath>(e, path);
  Schedule schedule;
  schedule.tick(reg, 0.5);
  EXPECT_NEAR(reg.get<Camera>(e).position.x, 2.5f, 1e-5f);
  EXPECT_NEAR(reg.get<Camera>(e).look_at.x, 2.5f, 1e-5f);
  // A quarter of the way: the up turned a quarter-ish of the roll (normalised blend), a unit
  // vector between the two keys'.
  const vec3 up = reg.get<Camera>(e).up;
  EXPECT_NEAR(glm::length(up), 1.0f, 1e-6f);
  EXPECT_LT(up.x, 0.0f);
  EXPECT_GT(up.y, 0.0f);
  schedule.tick(reg, 10.0);
  EXPECT_NEAR(reg.get<Camera>(e).position.x, 10.0f, 1e-5f);
}

TEST(Systems, VisibilityKeysHideAnEntityAndItsSubtreeLightsIncluded) {
  ecs::Registry reg;
  const ecs::Entity parent = reg.create();
  Transform t;
  t.translation = dvec3(1, 2, 3);
  t.scale = vec3(2.0f);
  reg.emplace<Transform>(parent, t);
  Animation a;
  a.loop = false;
  a.visibility.times = {0.5f, 1.5f}; // hidden from 0.5 s (and before: the first key's state)
  a.visibility.visible = {0, 1};     // shown again from 1.5 s
  reg.emplace<Animation>(parent, a);
  const ecs::Entity child = reg.create();
  Transform ct;
  ct.translation = dvec3(0, 1, 0);
  reg.emplace<Transform>(child, ct);
  reg.emplace<Parent>(child, Parent{parent});
  reg.emplace<Light>(child);
  // Switching visibility moves the subtree (its world transforms collapse): not static.
  EXPECT_EQ(inferred_kinematics(reg, child), Kinematics::Type::Hierarchical);
  SceneLayer& layer = reg.set_resource<SceneLayer>();
  Schedule schedule;

  schedule.tick(reg, 0.75);
  EXPECT_TRUE(reg.has<Hidden>(parent));
  for (const ecs::Entity e : {parent, child}) {
    const dmat4& w = reg.get<WorldTransform>(e).world_from_object;
    EXPECT_EQ(dmat3(w), dmat3(0.0)) << "collapsed while hidden";
    EXPECT_EQ(dvec3(w[3]), dvec3(1, 2, 3)) << "at the hidden entity's origin";
  }
  EXPECT_TRUE(layer.tables().lights.empty()) << "a light under a hidden entity is off";

  schedule.tick(reg, 1.0); // t = 1.75
  EXPECT_FALSE(reg.has<Hidden>(parent));
  EXPECT_EQ(reg.get<WorldTransform>(parent).world_from_object, t.parent_from_local());
  EXPECT_EQ(reg.get<WorldTransform>(child).world_from_object,
            t.parent_from_local() * ct.parent_from_local());
  EXPECT_EQ(layer.tables().lights.size(), 1u);

  // Hidden again, then the switches removed (an editor deleting the animation): shown.
  reg.get<Animation>(parent).time = 0.0f;
  schedule.tick(reg, 0.1);
  EXPECT_TRUE(reg.has<Hidden>(parent));
  reg.get<Animation>(parent).visibility = {};
  schedule.tick(reg, 0.1);
  EXPECT_FALSE(reg.has<Hidden>(parent));
  EXPECT_EQ(layer.tables().lights.size(), 1u);
}

TEST(Systems, ScheduleRunsAnimationTransformSceneLayerAccelerationCachesRenderInThatOrder) {
  const auto names = Schedule::system_names();
  ASSERT_EQ(names.size(), 6u);
  EXPECT_EQ(names[0], "animation");
  EXPECT_EQ(names[1], "transform");
  EXPECT_EQ(names[2], "scene_layer");
  EXPECT_EQ(names[3], "acceleration");
  EXPECT_EQ(names[4], "cache_invalidation");
  EXPECT_EQ(names[5], "render");
  // The order matters: an animated entity's world transform reflects this tick's animation.
  ecs::Registry reg;
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e);
  Animation anim;
  anim.loop = false;
  anim.translation.times = {0.0f, 1.0f};
  anim.translation.values = {vec3(0), vec3(1, 0, 0)};
  reg.emplace<Animation>(e, anim);
  Schedule schedule;
  schedule.tick(reg, 0.5);
  EXPECT_NEAR(reg.get<WorldTransform>(e).world_from_object[3].x, 0.5f, 1e-6f);
}

} // namespace
} // namespace specula
