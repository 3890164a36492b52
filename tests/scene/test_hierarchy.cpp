// update_world_transforms (engine/scene/hierarchy.h): the one place parent cycles are checked.

#include "specula/core/error.h"
#include "specula/scene/components.h"
#include "specula/scene/hierarchy.h"

#include <gtest/gtest.h>

#include <optional>
#include <string>

namespace specula {
namespace {

ecs::Entity add(ecs::Registry& reg, std::optional<std::string> name, float x = 0.0f) {
  const ecs::Entity e = reg.create();
  if (name) reg.emplace<Name>(e, Name{*name});
  Transform t;
  t.translation = vec3(x, 0.0f, 0.0f);
  reg.emplace<Transform>(e, t);
  return e;
}

void set_parent(ecs::Registry& reg, ecs::Entity child, ecs::Entity parent) {
  reg.emplace<Parent>(child, Parent{parent});
}

/// The message update_world_transforms throws ("" when it does not), checking that the error
/// names the context.
std::string hierarchy_error(ecs::Registry& reg) {
  try {
    (void)update_world_transforms(reg, 0, "scene.json");
  } catch (const Error& e) {
    EXPECT_EQ(e.file(), "scene.json") << e.what();
    return e.message();
  }
  return "";
}

TEST(Hierarchy, CycleIsAnErrorNamingItsEntitiesInParentOrder) {
  ecs::Registry reg;
  const ecs::Entity a = add(reg, "a");
  const ecs::Entity b = add(reg, "b");
  const ecs::Entity c = add(reg, "c");
  const ecs::Entity tail = add(reg, "tail"); // leads into the cycle, is not part of it
  set_parent(reg, a, c);
  set_parent(reg, c, b);
  set_parent(reg, b, a);
  set_parent(reg, tail, b);
  EXPECT_EQ(hierarchy_error(reg), "parent chain forms a cycle: \"a\" -> \"c\" -> \"b\" -> \"a\"")
      << "from the entity created first, whichever entity the walk starts at";
}

TEST(Hierarchy, OwnParentIsACycleOfOne) {
  ecs::Registry reg;
  (void)add(reg, "root");
  const ecs::Entity a = add(reg, "a");
  set_parent(reg, a, a);
  EXPECT_EQ(hierarchy_error(reg), "parent chain forms a cycle: \"a\" -> \"a\"");
}

TEST(Hierarchy, UnnamedEntitiesOfACycleAreNamedBySlot) {
  ecs::Registry reg;
  const ecs::Entity named = add(reg, "named");
  const ecs::Entity unnamed = add(reg, std::nullopt);
  const ecs::Entity empty = add(reg, "");
  set_parent(reg, named, unnamed);
  set_parent(reg, unnamed, empty);
  set_parent(reg, empty, named);
  EXPECT_EQ(hierarchy_error(reg), "parent chain forms a cycle: \"named\" -> entity " +
                                      std::to_string(unnamed.index) + " -> entity " +
                                      std::to_string(empty.index) + " -> \"named\"");
}

TEST(Hierarchy, StaleParentIsAnErrorNamingTheChild) {
  ecs::Registry reg;
  const ecs::Entity parent = add(reg, "parent");
  const ecs::Entity child = add(reg, "child");
  set_parent(reg, child, parent);
  reg.destroy(parent);
  EXPECT_EQ(hierarchy_error(reg), "\"child\" has a parent that no longer exists");
}

TEST(Hierarchy, ChainOf100kCreatedChildFirstIsComposedParentsFirst) {
  // Each link is one unit along +X from its parent; the leaf is created first and the root last,
  // so the order of the Transform pool is the reverse of the parent-first order.
  constexpr int kDepth = 100000;
  ecs::Registry reg;
  const ecs::Entity leaf = add(reg, "leaf", 1.0f);
  ecs::Entity child = leaf;
  for (int i = 1; i < kDepth; ++i) {
    const ecs::Entity parent = add(reg, std::nullopt, 1.0f);
    set_parent(reg, child, parent);
    child = parent;
  }
  EXPECT_EQ(hierarchy_error(reg), "");
  EXPECT_FLOAT_EQ(reg.get<WorldTransform>(leaf).world_from_object[3].x, float(kDepth));
}

} // namespace
} // namespace specula
