// The kinematics rules (engine/scene/kinematics_rules.h) on registries built in code.

#include "specula/core/error.h"
#include "specula/scene/components.h"
#include "specula/scene/kinematics_rules.h"

#include <gtest/gtest.h>

#include <optional>
#include <random>
#include <string>
#include <vector>

namespace specula {
namespace {

using Type = Kinematics::Type;

/// A two-key track of `V`, from `a` at t = 0 to `b` at t = 1.
template <typename V>
Keyframes<V> track(const V& a, const V& b) {
  Keyframes<V> k;
  k.times = {0.0f, 1.0f};
  k.values = {a, b};
  return k;
}

Animation translating() {
  Animation a;
  a.translation = track(dvec3(0.0), dvec3(1.0, 0.0, 0.0));
  return a;
}

Animation deforming() {
  Animation a;
  a.vertices = track(std::vector<vec3>{vec3(0.0f)}, std::vector<vec3>{vec3(1.0f)});
  return a;
}

/// An entity named `name` with a Transform, optionally a parent, a Mesh and an Animation.
ecs::Entity add(ecs::Registry& reg, const std::string& name, std::optional<ecs::Entity> parent,
                bool mesh, std::optional<Animation> animation = std::nullopt) {
  const ecs::Entity e = reg.create();
  reg.emplace<Name>(e, Name{name});
  reg.emplace<Transform>(e);
  if (parent) reg.emplace<Parent>(e, Parent{*parent});
  if (mesh) reg.emplace<Mesh>(e);
  if (animation) reg.emplace<Animation>(e, *animation);
  return e;
}

/// The message settle_kinematics throws ("" when it does not), checking that it names the file.
std::string settle_error(ecs::Registry& reg) {
  try {
    settle_kinematics(reg, "rules.json");
  } catch (const Error& e) {
    EXPECT_EQ(e.file(), "rules.json") << e.what();
    return e.message();
  }
  return "";
}

TEST(InferredKinematics, NothingAnimatedIsStatic) {
  ecs::Registry reg;
  const ecs::Entity root = add(reg, "root", std::nullopt, true);
  const ecs::Entity child = add(reg, "child", root, true);
  EXPECT_EQ(inferred_kinematics(reg, root), Type::Static);
  EXPECT_EQ(inferred_kinematics(reg, child), Type::Static);
}

TEST(InferredKinematics, EachOwnTransformTrackMakesItHierarchical) {
  ecs::Registry reg;
  Animation rotating;
  rotating.rotation = track(quat(1, 0, 0, 0), glm::angleAxis(1.0f, vec3(0, 1, 0)));
  Animation scaling;
  scaling.scale = track(vec3(1.0f), vec3(2.0f));
  EXPECT_EQ(inferred_kinematics(reg, add(reg, "t", std::nullopt, true, translating())),
            Type::Hierarchical);
  EXPECT_EQ(inferred_kinematics(reg, add(reg, "r", std::nullopt, true, rotating)),
            Type::Hierarchical);
  EXPECT_EQ(inferred_kinematics(reg, add(reg, "s", std::nullopt, true, scaling)),
            Type::Hierarchical);
}

TEST(InferredKinematics, AnAncestorThreeLevelsUpMakesItHierarchical) {
  ecs::Registry reg;
  const ecs::Entity arm = add(reg, "arm", std::nullopt, false, translating());
  const ecs::Entity forearm = add(reg, "forearm", arm, false);
  const ecs::Entity wrist = add(reg, "wrist", forearm, false);
  const ecs::Entity hand = add(reg, "hand", wrist, true);
  const ecs::Entity bystander = add(reg, "bystander", std::nullopt, true);
  EXPECT_EQ(inferred_kinematics(reg, hand), Type::Hierarchical);
  EXPECT_EQ(inferred_kinematics(reg, bystander), Type::Static);
}

TEST(InferredKinematics, VertexAnimationIsFreeAndMovesNoDescendant) {
  ecs::Registry reg;
  const ecs::Entity blob = add(reg, "blob", std::nullopt, true, deforming());
  const ecs::Entity rider = add(reg, "rider", blob, true);
  EXPECT_EQ(inferred_kinematics(reg, blob), Type::Free);
  EXPECT_EQ(inferred_kinematics(reg, rider), Type::Static)
      << "the ancestor's mesh deforms, its transform stays";
  const ecs::Entity mover = add(reg, "mover", std::nullopt, false, translating());
  EXPECT_EQ(inferred_kinematics(reg, add(reg, "moved blob", mover, true, deforming())), Type::Free)
      << "deforming wins over being moved";
}

TEST(InferredKinematics, AParentCycleGivesAnAnswerInsteadOfHanging) {
  ecs::Registry reg;
  const ecs::Entity a = add(reg, "a", std::nullopt, true);
  const ecs::Entity b = add(reg, "b", a, true);
  reg.emplace<Parent>(a, Parent{b});
  EXPECT_EQ(inferred_kinematics(reg, a), Type::Static);
  reg.emplace<Animation>(b, translating());
  EXPECT_EQ(inferred_kinematics(reg, a), Type::Hierarchical);
}

TEST(SettleKinematics, InfersForMeshEntitiesOnly) {
  ecs::Registry reg;
  const ecs::Entity arm = add(reg, "arm", std::nullopt, false, translating());
  const ecs::Entity hand = add(reg, "hand", arm, true);
  const ecs::Entity rock = add(reg, "rock", std::nullopt, true);
  const ecs::Entity blob = add(reg, "blob", std::nullopt, true, deforming());
  settle_kinematics(reg, "rules.json");
  EXPECT_FALSE(reg.has<Kinematics>(arm)) << "no mesh, no acceleration structure";
  EXPECT_EQ(reg.get<Kinematics>(hand).type, Type::Hierarchical);
  EXPECT_EQ(reg.get<Kinematics>(rock).type, Type::Static);
  EXPECT_EQ(reg.get<Kinematics>(blob).type, Type::Free);
}

TEST(SettleKinematics, KeepsStatedKinematicsThatAllowTheMotion) {
  ecs::Registry reg;
  const ecs::Entity rock = add(reg, "rock", std::nullopt, true);
  reg.emplace<Kinematics>(rock, Kinematics{Type::Free});
  const ecs::Entity arm = add(reg, "arm", std::nullopt, true, translating());
  reg.emplace<Kinematics>(arm, Kinematics{Type::Free});
  EXPECT_EQ(settle_error(reg), "");
  EXPECT_EQ(reg.get<Kinematics>(rock).type, Type::Free) << "more freedom than needed is allowed";
  EXPECT_EQ(reg.get<Kinematics>(arm).type, Type::Free);
}

TEST(SettleKinematics, StaticMovedByAnAncestorIsAnErrorNamingBoth) {
  ecs::Registry reg;
  const ecs::Entity arm = add(reg, "arm", std::nullopt, false, translating());
  const ecs::Entity forearm = add(reg, "forearm", arm, false);
  const ecs::Entity hand = add(reg, "hand", forearm, true);
  reg.emplace<Kinematics>(hand, Kinematics{Type::Static});
  EXPECT_EQ(settle_error(reg),
            "kinematics of \"hand\" is \"static\" but it is moved by the animation of its "
            "ancestor \"arm\": use \"hierarchical\" or \"free\"");
}

TEST(SettleKinematics, StaticMovedByItsOwnAnimationIsAnError) {
  ecs::Registry reg;
  const ecs::Entity door = add(reg, "door", std::nullopt, true, translating());
  reg.emplace<Kinematics>(door, Kinematics{Type::Static});
  EXPECT_EQ(settle_error(reg), "kinematics of \"door\" is \"static\" but it is moved by its own "
                               "animation: use \"hierarchical\" or \"free\"");
}

TEST(SettleKinematics, StaticOnAMovedEntityWithoutMeshIsAnErrorToo) {
  ecs::Registry reg;
  const ecs::Entity pivot = add(reg, "pivot", std::nullopt, false, translating());
  reg.emplace<Kinematics>(pivot, Kinematics{Type::Static});
  EXPECT_NE(settle_error(reg).find("\"pivot\""), std::string::npos);
}

TEST(SettleKinematics, DeformingButNotFreeIsAnError) {
  for (const Type stated : {Type::Static, Type::Hierarchical}) {
    ecs::Registry reg;
    const ecs::Entity blob = add(reg, "blob", std::nullopt, true, deforming());
    reg.emplace<Kinematics>(blob, Kinematics{stated});
    EXPECT_EQ(settle_error(reg), "kinematics of \"blob\" is \"" +
                                     std::string(kinematics_name(stated)) +
                                     "\" but its vertex animation deforms its mesh: use \"free\"");
  }
}

TEST(SettleKinematics, UnnamedEntitiesAreNamedBySlot) {
  ecs::Registry reg;
  const ecs::Entity e = reg.create();
  reg.emplace<Mesh>(e);
  reg.emplace<Animation>(e, translating());
  reg.emplace<Kinematics>(e, Kinematics{Type::Static});
  EXPECT_NE(settle_error(reg).find("kinematics of entity " + std::to_string(e.index) + " is"),
            std::string::npos);
}

TEST(SettleKinematics, AgreesWithInferredKinematicsOnARandomForest) {
  // settle_kinematics memoises ancestor lookups, inferred_kinematics walks each chain: the two
  // must give the same answer for every entity.
  std::mt19937 rng(20240917);
  ecs::Registry reg;
  std::vector<ecs::Entity> entities;
  for (int i = 0; i < 2000; ++i) {
    std::optional<ecs::Entity> parent;
    if (!entities.empty() && rng() % 4 != 0) parent = entities[rng() % entities.size()];
    std::optional<Animation> animation;
    switch (rng() % 10) {
    case 0:
      animation = translating();
      break;
    case 1:
      animation = deforming();
      break;
    default:
      break;
    }
    entities.push_back(add(reg, "e" + std::to_string(i), parent, rng() % 3 != 0, animation));
  }
  std::vector<std::optional<Type>> expected;
  for (const ecs::Entity e : entities)
    expected.push_back(reg.has<Mesh>(e) ? std::optional(inferred_kinematics(reg, e))
                                        : std::nullopt);
  settle_kinematics(reg, "forest.json");
  int hierarchical = 0;
  for (std::size_t i = 0; i < entities.size(); ++i) {
    ASSERT_EQ(reg.has<Kinematics>(entities[i]), expected[i].has_value()) << i;
    if (!expected[i]) continue;
    EXPECT_EQ(reg.get<Kinematics>(entities[i]).type, *expected[i]) << i;
    hierarchical += *expected[i] == Type::Hierarchical ? 1 : 0;
  }
  EXPECT_GT(hierarchical, 100) << "the forest should exercise inherited motion";
}

TEST(SettleKinematics, SettlesAChainOf100kUnderAnAnimatedRoot) {
  // Memoised: O(n) for a chain, where walking each entity's ancestors would be O(n²).
  constexpr int kDepth = 100000;
  ecs::Registry reg;
  std::optional<ecs::Entity> prev = add(reg, "root", std::nullopt, true, translating());
  for (int i = 1; i < kDepth; ++i) prev = add(reg, "link", prev, true);
  settle_kinematics(reg, "chain.json");
  EXPECT_EQ(reg.count<Kinematics>(), std::size_t(kDepth));
  int hierarchical = 0;
  reg.view<Kinematics>().each(
      [&](const Kinematics& k) { hierarchical += k.type == Type::Hierarchical ? 1 : 0; });
  EXPECT_EQ(hierarchical, kDepth);
}

} // namespace
} // namespace specula
