// The two-level Embree structure: only entities that changed cause work.

#include "specula/accel/embree/embree_accel.h"
#include "specula/accel/embree/embree_backend.h"
#include "scene_builder.h"
#include "specula/systems/schedule.h"
#include "specula/trace/camera_rays.h"
#include "specula/trace/packet_tile.h"

#include <algorithm>

#include <gtest/gtest.h>

namespace specula {
namespace {

struct World {
  ecs::Registry reg;
  ecs::Entity ground, pillar, ball, twin, blob;
  World() {
    ground = test::add_mesh(reg, test::primitive("plane", 1, vec3(20, 1, 20)), test::at(vec3(0)));
    pillar = test::add_mesh(reg, test::primitive("box", 1, vec3(1, 4, 1)), test::at(vec3(-3, 2, 0)));
    const MeshSource sphere = test::primitive("sphere", 1.0f);
    ball = test::add_mesh(reg, sphere, test::at(vec3(2, 1, 0)), Material{}, Kinematics::Type::Free);
    // Same TriangleMesh as the ball: one shared per-mesh structure for both instances.
    twin = reg.create();
    reg.emplace<Transform>(twin, test::at(vec3(5, 1, 0)));
    reg.emplace<Mesh>(twin, reg.get<Mesh>(ball));
    reg.emplace<Material>(twin);
    reg.emplace<Kinematics>(twin, Kinematics{Kinematics::Type::Hierarchical});
    // Becomes a deforming mesh (own structure, refitted) in the test that animates it.
    blob = test::add_mesh(reg, test::primitive("sphere", 0.5f, vec3(1), 16, 8), test::at(vec3(0, 1, 4)),
                          Material{}, Kinematics::Type::Free);
    reg.set_resource<EmbreeAccel>();
  }
  EmbreeAccel& accel() { return reg.resource<EmbreeAccel>(); }
};

/// The closest hit of a ray cast straight down from 10 units above (x, z).
Hit hit_below(World& w, float x, float z) {
  const EmbreeBackend backend(w.accel(), 1);
  Ray down;
  down.origin = vec3(x, 10, z);
  down.direction = vec3(0, -1, 0);
  Hit hit;
  backend.intersect(down, hit);
  return hit;
}

TEST(EmbreeAccel, FirstUpdateBuildsStaticOnceAndOneStructurePerMesh) {
  World w;
  Schedule schedule;
  schedule.tick(w.reg, 0.0);
  const AccelUpdateStats& s = w.accel().last_update();
  EXPECT_EQ(s.static_builds, 1u);
  EXPECT_EQ(s.blas_builds, 2u); // the shared sphere and the blob
  EXPECT_EQ(s.instances_added, 3u);
  EXPECT_TRUE(s.top_committed);
  EXPECT_EQ(s.static_triangles, w.reg.get<Mesh>(w.ground).geometry->triangle_count() +
                                    w.reg.get<Mesh>(w.pillar).geometry->triangle_count());
  EXPECT_EQ(w.accel().surfaces().size(), 5u);
}

TEST(EmbreeAccel, AnUnchangedFrameDoesNoWork) {
  World w;
  Schedule schedule;
  schedule.tick(w.reg, 0.0);
  schedule.tick(w.reg, 1.0 / 60.0);
  const AccelUpdateStats& s = w.accel().last_update();
  EXPECT_EQ(s.static_builds + s.blas_builds + s.blas_refits + s.instances_added + s.instances_moved +
                s.instances_removed,
            0u);
  EXPECT_FALSE(s.top_committed);
}

TEST(EmbreeAccel, MovingOneObjectRewritesOnlyItsInstance) {
  World w;
  Schedule schedule;
  schedule.tick(w.reg, 0.0);
  w.reg.get<Transform>(w.ball).translation.x += 1.0f;
  schedule.tick(w.reg, 1.0 / 60.0);
  const AccelUpdateStats& s = w.accel().last_update();
  EXPECT_EQ(s.instances_moved, 1u);
  EXPECT_EQ(s.static_builds, 0u);
  EXPECT_EQ(s.blas_builds, 0u);
  EXPECT_TRUE(s.top_committed);

  // And the moved ball is where the ray now finds it.
  const Hit hit = hit_below(w, 3, 0);
  ASSERT_TRUE(hit.hit());
  EXPECT_EQ(w.accel().surfaces()[hit.surface].entity, w.ball);
  EXPECT_NEAR(hit.t, 8.0f, 0.01f);
  EXPECT_NEAR(w.accel().surfaces()[hit.surface].world_normal(hit.object_normal).y, 1.0f, 0.05f);
}

TEST(EmbreeAccel, DeformingMeshIsRefittedNotRebuilt) {
  World w;
  Animation anim;
  const auto& base = w.reg.get<Mesh>(w.blob).geometry->positions;
  std::vector<vec3> stretched = base;
  for (vec3& p : stretched) p.y *= 2.0f;
  anim.vertices.times = {0.0f, 1.0f};
  anim.vertices.values = {base, stretched};
  w.reg.emplace<Animation>(w.blob, anim);
  Schedule schedule;
  schedule.tick(w.reg, 0.0);
  EXPECT_EQ(w.accel().last_update().blas_builds, 2u);
  schedule.tick(w.reg, 0.5);
  const AccelUpdateStats& s = w.accel().last_update();
  EXPECT_EQ(s.blas_refits, 1u);
  EXPECT_EQ(s.blas_builds, 0u);
  EXPECT_EQ(s.static_builds, 0u);
  // Half-way: the blob's top is at 1 + 0.5 * 1.5 = 1.75.
  const Hit hit = hit_below(w, 0, 4);
  ASSERT_TRUE(hit.hit());
  EXPECT_EQ(w.accel().surfaces()[hit.surface].entity, w.blob);
  EXPECT_NEAR(10.0f - hit.t, 1.75f, 0.01f);
}

TEST(EmbreeAccel, DestroyedEntitiesLeaveTheStructure) {
  World w;
  Schedule schedule;
  schedule.tick(w.reg, 0.0);
  w.reg.destroy(w.twin);
  schedule.tick(w.reg, 0.0);
  EXPECT_EQ(w.accel().last_update().instances_removed, 1u);
  EXPECT_EQ(w.accel().last_update().static_builds, 0u);
  EXPECT_EQ(w.accel().surfaces().size(), 4u);
  const Hit hit = hit_below(w, 5, 0);
  ASSERT_TRUE(hit.hit());
  EXPECT_EQ(w.accel().surfaces()[hit.surface].entity, w.ground);
}

TEST(EmbreeAccel, MovingAStaticEntityRebuildsTheStaticSet) {
  World w;
  Schedule schedule;
  schedule.tick(w.reg, 0.0);
  w.reg.get<Transform>(w.pillar).translation.z = 3.0f; // not supposed to happen, but must be right
  schedule.tick(w.reg, 0.0);
  EXPECT_EQ(w.accel().last_update().static_builds, 1u);
  EXPECT_EQ(w.accel().last_update().instances_moved, 0u);
}

TEST(EmbreeAccel, PacketsAndSingleRaysFindTheSameHits) {
  World w;
  Schedule schedule;
  schedule.tick(w.reg, 0.0);
  Camera camera;
  camera.position = vec3(0, 6, 12);
  camera.look_at = vec3(0, 0, 0);
  const CameraRays rays(camera, 64, 64);
  // A 23×23 tile: partial blocks at its right and bottom edges for every footprint.
  std::vector<Hit> reference(23 * 23);
  EmbreeBackend(w.accel(), 1).intersect_camera(rays, PacketTile::for_width(5, 7, 28, 30, 1), reference);
  std::vector<std::pair<std::uint32_t, std::uint32_t>> reference_pixels;
  PacketTile::for_width(5, 7, 28, 30, 1).for_each_pixel([&](std::uint32_t x, std::uint32_t y) {
    reference_pixels.emplace_back(x, y);
  });
  for (const std::uint32_t width : {4u, 8u, 16u}) {
    const PacketTile tile = PacketTile::for_width(5, 7, 28, 30, width);
    std::vector<Hit> hits(tile.pixel_count());
    EmbreeBackend(w.accel(), width).intersect_camera(rays, tile, hits);
    std::size_t i = 0;
    tile.for_each_pixel([&](std::uint32_t x, std::uint32_t y) {
      const auto at = std::find(reference_pixels.begin(), reference_pixels.end(), std::make_pair(x, y));
      ASSERT_NE(at, reference_pixels.end());
      const Hit& ref = reference[std::size_t(at - reference_pixels.begin())];
      EXPECT_EQ(hits[i].surface, ref.surface) << width << " pixel " << x << "," << y;
      // The primitive may differ where a ray meets a shared edge exactly: either is right.
      EXPECT_FLOAT_EQ(hits[i].t, ref.t) << width << " pixel " << x << "," << y;
      ++i;
    });
    EXPECT_EQ(i, reference_pixels.size());
  }
}

} // namespace
} // namespace specula
