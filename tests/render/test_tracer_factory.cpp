// The tracer factory: names, availability, and `auto`'s choice by the scene's kind.
#include "scene_builder.h"
#include "specula/core/error.h"
#include "specula/render/tracer_factory.h"

#include <gtest/gtest.h>

namespace specula {
namespace {

TEST(TracerFactory, SceneKindFollowsKinematicsAndVertexAnimation) {
  ecs::Registry reg;
  test::add_mesh(reg, test::primitive("box"), test::at(vec3(0)));
  EXPECT_EQ(scene_kind(reg), SceneKind::static_only);
  test::add_mesh(reg, test::primitive("sphere"), test::at(vec3(3, 0, 0)), Material{},
                 Kinematics::Type::Free);
  EXPECT_EQ(scene_kind(reg), SceneKind::rigid_dynamic);
  const ecs::Entity blob = test::add_mesh(reg, test::primitive("sphere"), test::at(vec3(-3, 0, 0)),
                                          Material{}, Kinematics::Type::Free);
  Animation anim;
  const auto& rest = reg.get<Mesh>(blob).geometry->positions;
  anim.vertices.times = {0.0f, 1.0f};
  anim.vertices.values = {rest, rest};
  reg.emplace<Animation>(blob, anim);
  EXPECT_EQ(scene_kind(reg), SceneKind::deforming);
}

TEST(TracerFactory, AutoTakesTheFirstAvailableCpuBackendInTheKindsOrder) {
  for (const SceneKind kind : {SceneKind::static_only, SceneKind::rigid_dynamic,
                               SceneKind::deforming}) {
    std::string expected;
    for (const std::string_view name : cpu_preference(kind))
      if (expected.empty() && backend_info(name).available) expected = std::string(name);
    if (backend_info("vulkan").available) expected = "vulkan";
    EXPECT_EQ(resolve_backend("auto", kind), expected) << scene_kind_name(kind);
    EXPECT_EQ(make_tracer("auto", 1, kind)->name(), expected);
  }
}

TEST(TracerFactory, EveryAvailableBackendMakesATracerOfThatName) {
  for (const BackendInfo& b : backends()) {
    if (!b.available) {
      EXPECT_THROW((void)make_tracer(b.name), UnavailableError) << b.name;
      continue;
    }
    EXPECT_EQ(make_tracer(b.name)->name(), b.name);
  }
  EXPECT_TRUE(backend_info("native").available) << "the native backend is in every build";
  EXPECT_TRUE(backend_info("native").watertight);
  EXPECT_THROW((void)backend_info("optix"), Error);
  EXPECT_THROW((void)resolve_backend("optix"), Error);
}

} // namespace
} // namespace specula
