// Numerical hardening of the tracers (issue 13): degenerate moving instances never reach a
// backend's builder, radiance stays finite for every accepted light, and a non-finite sample is
// counted and written as 0, never silently.

#include "scene_builder.h"
#include "specula/accel/common/traceable_instance.h"
#include "specula/render/render_job.h"
#include "specula/systems/schedule.h"
#include "specula/trace/lights.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

namespace specula {
namespace {

struct Frame {
  Framebuffer image{1, 1};
  FrameStats stats;
};

/// One frame through the schedule on `backend`, `width` × `height`, 2 threads.
Frame render(ecs::Registry& reg, const std::string& backend, TraceMode mode, std::uint32_t width,
             std::uint32_t height) {
  RenderJob job;
  job.backend = backend;
  job.settings.mode = mode;
  job.settings.threads = 2;
  job.image = Framebuffer(width, height);
  prepare_rendering(reg, std::move(job));
  Schedule schedule;
  schedule.tick(reg, 0.0);
  const RenderJob& done = reg.resource<RenderJob>();
  return {done.image, done.last};
}

int nonfinite_pixels(const Framebuffer& f) {
  int n = 0;
  for (const vec3& p : f.pixels()) n += is_finite(p) ? 0 : 1;
  return n;
}

// ---- Degenerate instances -----------------------------------------------------------------------

TEST(TraceableInstance, RegularTransformsAreTraceable) {
  const Aabb unit{vec3(-1.0f), vec3(1.0f)};
  EXPECT_TRUE(accel::traceable_instance(mat4(1.0f), unit));
  EXPECT_TRUE(accel::traceable_instance(compose_trs(vec3(3, -2, 1e5f), glm::angleAxis(0.7f, vec3(0, 1, 0)),
                                                    vec3(1e-4f, 2.0f, -3.0f)),
                                        unit));
  // A flat mesh (a plane) is fine: it has extent on two axes.
  EXPECT_TRUE(accel::traceable_instance(mat4(1.0f), Aabb{vec3(-1, 0, -1), vec3(1, 0, 1)}));
}

TEST(TraceableInstance, SingularTinyNonFiniteOrCollapsedAreNot) {
  const Aabb unit{vec3(-1.0f), vec3(1.0f)};
  const quat r = glm::angleAxis(0.3f, glm::normalize(vec3(1, 2, 3)));
  for (const vec3 scale : {vec3(0.0f), vec3(1e-20f), vec3(1e-38f), vec3(1, 0, 1), vec3(1, 1, 1e-30f)})
    EXPECT_FALSE(accel::traceable_instance(compose_trs(vec3(0, 1, 0), r, scale), unit))
        << scale.x << " " << scale.y << " " << scale.z;
  mat4 nan = mat4(1.0f);
  nan[3][0] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_FALSE(accel::traceable_instance(nan, unit));
  // Unit geometry at 1e30 is narrower than a float step there: a point.
  EXPECT_FALSE(accel::traceable_instance(compose_trs(vec3(1e30f), quat(1, 0, 0, 0), vec3(1)), unit));
  // A mesh whose triangles all sit on one point.
  EXPECT_FALSE(accel::traceable_instance(mat4(1.0f), Aabb{vec3(2.0f), vec3(2.0f)}));
  EXPECT_FALSE(accel::traceable_instance(mat4(1.0f), Aabb{})); // empty mesh
}

TEST(TraceableInstance, TheInverseOfATraceableInstanceIsFiniteAndUndoesIt) {
  // Near the limits: a rotated uniform scale of 2e-10 (det 8e-30) and a strongly non-uniform one
  // (unrotated: rotated, its condition number of 1e13 is beyond float whatever the inverse).
  const quat r = glm::angleAxis(0.4f, glm::normalize(vec3(1, 0, 2)));
  for (const mat4& m : {compose_trs(vec3(0.0f), r, vec3(2e-10f)),
                        compose_trs(vec3(0.0f), quat(1, 0, 0, 0), vec3(1e-9f, 1e4f, 3e3f))}) {
    ASSERT_TRUE(accel::traceable_instance(m, Aabb{vec3(-1.0f), vec3(1.0f)}));
    const mat4 inv(accel::inverse_affine(m));
    for (int c = 0; c < 4; ++c) EXPECT_TRUE(is_finite(inv[c]));
    const vec3 p = vec3(m * vec4(0.3f, -0.2f, 0.9f, 1.0f));
    const vec3 back = vec3(inv * vec4(p, 1.0f));
    EXPECT_NEAR(back.x, 0.3f, 1e-3f);
    EXPECT_NEAR(back.y, -0.2f, 1e-3f);
    EXPECT_NEAR(back.z, 0.9f, 1e-3f);
  }
}

class DegenerateInstances : public testing::TestWithParam<std::string> {};

/// A floor, a visible moving sphere, and `hidden` moving spheres and boxes with degenerate scales.
std::vector<ecs::Entity> degenerate_scene(ecs::Registry& reg, bool with_degenerate) {
  test::add_mesh(reg, test::primitive("plane", 1.0f, vec3(6.0f)), test::at(vec3(0)));
  test::add_mesh(reg, test::primitive("sphere", 0.5f), test::at(vec3(0.8f, 0.5f, 0)), Material{},
                 Kinematics::Type::Hierarchical);
  test::add_camera(reg, vec3(0, 1.5f, 4), vec3(0, 0.4f, 0));
  test::add_point_light(reg, vec3(1, 3, 2), 10.0f);
  std::vector<ecs::Entity> degenerate;
  if (!with_degenerate) return degenerate;
  // Several at one spot: Embree's top-level builder asserted on a set of point-sized boxes.
  const vec3 scales[] = {vec3(0.0f), vec3(1e-20f), vec3(1e-38f), vec3(1, 0, 1), vec3(0.0f),
                         vec3(1e-20f)};
  int k = 0;
  for (const vec3& s : scales) {
    const char* shape = k % 2 == 0 ? "sphere" : "box";
    degenerate.push_back(test::add_mesh(reg, test::primitive(shape, 0.5f),
                                        test::at(vec3(-0.7f, 0.5f, 0.2f * float(k % 3)), s),
                                        Material{}, Kinematics::Type::Hierarchical));
    ++k;
  }
  return degenerate;
}

TEST_P(DegenerateInstances, AreLeftOutCountedAndInvisible) {
  ecs::Registry reference_reg;
  degenerate_scene(reference_reg, false);
  const Frame reference = render(reference_reg, GetParam(), TraceMode::Whitted, 48, 32);

  ecs::Registry reg;
  const std::vector<ecs::Entity> degenerate = degenerate_scene(reg, true);
  const Frame frame = render(reg, GetParam(), TraceMode::Whitted, 48, 32);
  EXPECT_EQ(frame.stats.accel.hidden_instances, degenerate.size());
  EXPECT_EQ(nonfinite_pixels(frame.image), 0);
  // Nothing of them shows: the image is the scene without them, pixel for pixel.
  EXPECT_EQ(frame.image.pixels().size(), reference.image.pixels().size());
  int different = 0;
  for (std::size_t i = 0; i < frame.image.pixel_count(); ++i)
    different += frame.image.pixels()[i] == reference.image.pixels()[i] ? 0 : 1;
  EXPECT_EQ(different, 0);
}

TEST_P(DegenerateInstances, ScaleAnimatedToZeroAndBackHidesAndShowsTheObject) {
  ecs::Registry reg;
  test::add_mesh(reg, test::primitive("plane", 1.0f, vec3(6.0f)), test::at(vec3(0)));
  const ecs::Entity ball = test::add_mesh(reg, test::primitive("sphere", 0.5f),
                                          test::at(vec3(0, 0.5f, 0)), Material{},
                                          Kinematics::Type::Hierarchical);
  test::TracedWorld world(reg, GetParam());
  const Ray down{vec3(0, 3, 0), 0.0f, vec3(0, -1, 0), std::numeric_limits<float>::infinity()};
  const std::uint32_t ball_slot = world.intersect(down).instance;
  ASSERT_NE(ball_slot, kNoInstance);
  EXPECT_NEAR(world.intersect(down).t, 2.0f, 1e-3f); // the ball's top

  for (const vec3 s : {vec3(0.0f), vec3(1e-38f), vec3(1e-20f)}) {
    reg.get<Transform>(ball).scale = s;
    world.update(reg);
    EXPECT_EQ(world.tracer->last_update().hidden_instances, 1u);
    const Hit h = world.intersect(down);
    EXPECT_NEAR(h.t, 3.0f, 1e-5f) << "the floor, through where the ball was";
    EXPECT_FALSE(world.occluded(Ray{vec3(0, 3, 0), 0.0f, vec3(0, -1, 0), 2.9f}));
  }
  reg.get<Transform>(ball).scale = vec3(1.0f);
  world.update(reg);
  EXPECT_EQ(world.tracer->last_update().hidden_instances, 0u);
  EXPECT_NEAR(world.intersect(down).t, 2.0f, 1e-3f);
}

INSTANTIATE_TEST_SUITE_P(Backends, DegenerateInstances,
                         testing::ValuesIn(test::available_backends()),
                         [](const auto& p) { return test::test_name(p.param); });

} // namespace
} // namespace specula
