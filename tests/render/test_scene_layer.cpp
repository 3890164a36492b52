// The scene layer: the ECS turned into flat tables and a delta, once for every backend. Change
// comes from the transform system's moved list, deformation ticks and pool versions; a frame in
// which nothing changed does no work proportional to the scene.

#include "../trace/scene_builder.h"
#include "specula/render/scene_layer.h"
#include "specula/systems/animation_system.h"
#include "specula/systems/transform_system.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <type_traits>

namespace specula {
namespace {

static_assert(std::is_trivially_copyable_v<gpu::GpuInstance> &&
                  std::is_trivially_copyable_v<gpu::GpuMesh> &&
                  std::is_trivially_copyable_v<gpu::GpuMaterial> &&
                  std::is_trivially_copyable_v<gpu::GpuLight>,
              "the tables are uploaded to a GPU as they are: no pointers, no owning members");

/// One tick of the systems that feed the layer, then the layer's sync.
struct Ticker {
  std::uint64_t tick = 0;
  const SceneDelta& operator()(ecs::Registry& reg, SceneLayer& layer, double dt = 1.0 / 60.0) {
    FrameContext ctx;
    ctx.tick = ++tick;
    ctx.dt = dt;
    animation_system(reg, ctx);
    transform_system(reg, ctx);
    return layer.sync(reg);
  }
};

struct World {
  ecs::Registry reg;
  ecs::Entity ground, pillar, ball, twin, blob, lamp;
  World() {
    Material red;
    red.base_color = vec3(0.8f, 0.1f, 0.1f);
    ground = test::add_mesh(reg, test::primitive("plane", 1, vec3(20, 1, 20)), test::at(vec3(0)));
    pillar = test::add_mesh(
        reg, test::primitive("box", 1, vec3(1, 4, 1)),
        test::at(vec3(-3, 2, 0), vec3(1, 2, 1), glm::angleAxis(0.3f, vec3(0, 1, 0))), red);
    ball = test::add_mesh(reg, test::primitive("sphere", 1.0f), test::at(vec3(2, 1, 0)), Material{},
                          Kinematics::Type::Free);
    twin = reg.create();
    reg.emplace<Transform>(twin, test::at(vec3(5, 1, 0)));
    reg.emplace<Mesh>(twin, reg.get<Mesh>(ball)); // the same TriangleMesh as the ball
    reg.emplace<Kinematics>(twin, Kinematics{Kinematics::Type::Hierarchical});
    blob = test::add_mesh(reg, test::primitive("sphere", 0.5f, vec3(1), 16, 8),
                          test::at(vec3(0, 1, 4)), Material{}, Kinematics::Type::Free);
    Animation anim;
    const auto& base = reg.get<Mesh>(blob).geometry->positions;
    std::vector<vec3> stretched = base;
    for (vec3& p : stretched) p.y *= 2.0f;
    anim.vertices.times = {0.0f, 1.0f};
    anim.vertices.values = {base, stretched};
    anim.speed = 0.0f; // still until a test starts it
    reg.emplace<Animation>(blob, anim);
    lamp = test::add_point_light(reg, vec3(0, 8, 0), 50.0f);
  }
};

TEST(SceneLayer, TheFirstSyncBakesTheStaticSetInWorldSpaceAndPlacesTheRest) {
  World w;
  SceneLayer layer;
  Ticker tick;
  const SceneDelta& d = tick(w.reg, layer);
  const SceneTables& t = layer.tables();
  EXPECT_TRUE(d.static_rebuilt);
  EXPECT_EQ(d.instances_added.size(), 3u); // ball, twin, blob
  EXPECT_EQ(d.meshes_added.size(), 2u);    // the shared sphere (ball and twin) and the blob's
  ASSERT_EQ(t.static_instances.size(), 2u);
  EXPECT_EQ(t.entity(t.static_instances[0]), w.ground); // entity order
  EXPECT_EQ(t.entity(t.static_instances[1]), w.pillar);
  // The pillar's baked vertices are its object-space vertices placed by its world transform.
  const gpu::GpuInstance& pillar = t.instances[t.static_instances[1]];
  EXPECT_TRUE((pillar.flags & gpu::kInstanceStatic) && (pillar.flags & gpu::kInstanceIdentity));
  const gpu::GpuMesh& baked = t.meshes[pillar.mesh];
  const TriangleMesh& source = *w.reg.get<Mesh>(w.pillar).geometry;
  const mat4& m = w.reg.get<WorldTransform>(w.pillar).world_from_object;
  ASSERT_EQ(baked.vertex_count, source.positions.size());
  for (std::size_t i = 0; i < source.positions.size(); ++i)
    EXPECT_EQ(t.positions[baked.first_vertex + i], vec3(m * vec4(source.positions[i], 1.0f)));
  EXPECT_EQ(t.static_triangle_count,
            w.reg.get<Mesh>(w.ground).geometry->triangle_count() + source.triangle_count());
  EXPECT_EQ(t.materials[pillar.material].base_color, vec3(0.8f, 0.1f, 0.1f));
  // Ball and twin share one mesh record; the blob deforms, so it owns its vertices.
  const gpu::GpuInstance& ball = t.instances[*layer.instance_of(w.ball)];
  const gpu::GpuInstance& twin = t.instances[*layer.instance_of(w.twin)];
  const gpu::GpuInstance& blob = t.instances[*layer.instance_of(w.blob)];
  EXPECT_EQ(ball.mesh, twin.mesh);
  EXPECT_EQ(ball.kinematics, gpu::kKinematicsFree);
  EXPECT_EQ(twin.kinematics, gpu::kKinematicsHierarchical);
  EXPECT_TRUE(blob.flags & gpu::kInstanceDeforming);
  EXPECT_EQ(t.meshes[blob.mesh].first_normal, gpu::kNoIndex); // deformed: geometric normals
  EXPECT_EQ(vec3(twin.world_from_object[3]), vec3(5, 1, 0));
  EXPECT_NEAR(twin.world_bounds_min.x, 4.0f, 1e-5f);
  EXPECT_NEAR(twin.world_bounds_max.x, 6.0f, 1e-5f);
  ASSERT_EQ(t.lights.size(), 1u);
  EXPECT_EQ(t.lights[0].position, vec3(0, 8, 0));
  EXPECT_FALSE(layer.instance_of(w.lamp).has_value());
}

/// Camera-relative render space (docs/design/large-worlds.md): the render origin stays at the
/// world origin while the camera is within kRebaseDistance of it, then moves to the camera; the
/// tables become world minus origin in float, as a fresh layer would write them there.
TEST(SceneLayer, TheRenderOriginFollowsTheCameraPastTheRebaseDistance) {
  World w;
  const ecs::Entity cam = test::add_camera(w.reg, vec3(0, 2, 10), vec3(0));
  SceneLayer layer;
  Ticker tick;
  tick(w.reg, layer);
  EXPECT_EQ(layer.render_origin(), dvec3(0.0));

  // Within the distance: nothing is rewritten.
  w.reg.get<Camera>(cam).position = dvec3(kRebaseDistance - 20.0, 2.0, 10.0);
  EXPECT_TRUE(tick(w.reg, layer).empty());
  EXPECT_EQ(layer.stats().rebases, 0u);
  EXPECT_EQ(layer.render_origin(), dvec3(0.0));

  // Past it, in the same tick as an entity moves: one rebase; the static set is baked again and
  // every dynamic instance rewritten and reported once.
  const dvec3 far(1e6 + 0.25, 2.0, 10.0);
  w.reg.get<Camera>(cam).position = far;
  w.reg.get<Camera>(cam).look_at = far - dvec3(0.0, 0.0, 10.0);
  w.reg.get<Transform>(w.ball).translation += dvec3(0.5, 0.0, 0.0);
  const SceneDelta& d = tick(w.reg, layer);
  EXPECT_EQ(layer.stats().rebases, 1u);
  EXPECT_EQ(layer.rebases(), 1u);
  EXPECT_EQ(layer.render_origin(), far);
  EXPECT_TRUE(d.static_rebuilt);
  EXPECT_EQ(layer.stats().static_bakes, 1u);
  std::vector<std::uint32_t> moved = d.instances_moved;
  std::sort(moved.begin(), moved.end());
  EXPECT_EQ(std::unique(moved.begin(), moved.end()), moved.end()) << "each instance once";
  EXPECT_EQ(moved.size(), 3u); // ball, twin, blob
  EXPECT_TRUE(d.lights_changed);

  const SceneTables& t = layer.tables();
  const gpu::GpuInstance& pillar = t.instances[*layer.instance_of(w.pillar)];
  const gpu::GpuMesh& baked = t.meshes[pillar.mesh];
  const TriangleMesh& source = *w.reg.get<Mesh>(w.pillar).geometry;
  // Placed by the render-space matrix: the world matrix with the origin taken off its
  // translation in double, then rounded to float.
  dmat4 relative = w.reg.get<WorldTransform>(w.pillar).world_from_object;
  relative[3] -= dvec4(far, 0.0);
  const mat4 render_from_object(relative);
  for (std::size_t i = 0; i < source.positions.size(); ++i)
    EXPECT_EQ(t.positions[baked.first_vertex + i],
              vec3(render_from_object * vec4(source.positions[i], 1.0f)));
  const gpu::GpuInstance& twin = t.instances[*layer.instance_of(w.twin)];
  EXPECT_EQ(vec3(twin.world_from_object[3]), vec3(dvec3(5, 1, 0) - far));
  EXPECT_EQ(t.lights[0].position, vec3(dvec3(0, 8, 0) - far));

  // The same tables as a layer made with the camera already there.
  SceneLayer fresh;
  fresh.sync(w.reg);
  EXPECT_EQ(fresh.render_origin(), far);
  EXPECT_EQ(fresh.stats().rebases, 0u) << "the first sync's choice is not a rebase";
  const SceneTables& f = fresh.tables();
  ASSERT_EQ(f.static_triangle_count, t.static_triangle_count);
  EXPECT_TRUE(std::equal(f.positions.begin(),
                         f.positions.begin() + baked.first_vertex + baked.vertex_count,
                         t.positions.begin()));
  for (const ecs::Entity e : {w.ball, w.twin, w.blob})
    EXPECT_EQ(f.instances[*fresh.instance_of(e)].world_from_object,
              t.instances[*layer.instance_of(e)].world_from_object);
  EXPECT_EQ(f.lights[0].position, t.lights[0].position);
}

TEST(SceneLayer, AFrameInWhichNothingMovedDoesNoWork) {
  World w;
  SceneLayer layer;
  Ticker tick;
  tick(w.reg, layer);
  for (int i = 0; i < 3; ++i) {
    const SceneDelta& d = tick(w.reg, layer);
    EXPECT_TRUE(d.empty());
    const SceneLayerStats& s = layer.stats();
    EXPECT_EQ(s.full_scans, 0u);
    EXPECT_EQ(s.entities_visited, 0u); // not one entity looked at, static or not
    EXPECT_EQ(s.vertices_written, 0u);
    EXPECT_EQ(s.static_bakes + s.relayouts, 0u);
    EXPECT_EQ(s.static_instances, 2u);
    EXPECT_EQ(s.dynamic_instances, 3u);
  }
}

TEST(SceneLayer, AConsumerMissesOnlySyncsThatChangedSomething) {
  World w;
  SceneLayer layer;
  Ticker tick;
  tick(w.reg, layer); // sync 1: everything added
  tick(w.reg, layer); // 2: still
  tick(w.reg, layer); // 3: still
  EXPECT_FALSE(layer.missed_changes(2)) << "in step";
  EXPECT_FALSE(layer.missed_changes(1)) << "sync 2 changed nothing";
  EXPECT_TRUE(layer.missed_changes(0)) << "sync 1 added everything";
  w.reg.get<Transform>(w.ball).translation = vec3(2, 3, -1);
  tick(w.reg, layer); // 4: the ball moved
  EXPECT_FALSE(layer.missed_changes(2)) << "the change is the latest delta itself";
  tick(w.reg, layer); // 5: still
  EXPECT_FALSE(layer.missed_changes(4));
  EXPECT_TRUE(layer.missed_changes(3)) << "sync 4 moved the ball";
  EXPECT_TRUE(layer.missed_changes(2));
}

TEST(SceneLayer, OneFreeEntityMovedIsOneInstanceUpdate) {
  World w;
  SceneLayer layer;
  Ticker tick;
  tick(w.reg, layer);
  w.reg.get<Transform>(w.ball).translation = vec3(2, 3, -1);
  const SceneDelta& d = tick(w.reg, layer);
  const std::uint32_t slot = *layer.instance_of(w.ball);
  ASSERT_EQ(d.instances_moved.size(), 1u);
  EXPECT_EQ(d.instances_moved[0], slot);
  EXPECT_FALSE(d.static_rebuilt);
  EXPECT_TRUE(d.instances_added.empty() && d.instances_removed.empty() &&
              d.instances_deformed.empty());
  EXPECT_EQ(layer.stats().entities_visited, 1u); // the moved one, from the transform system's list
  EXPECT_EQ(layer.stats().vertices_written, 0u);
  EXPECT_EQ(layer.stats().full_scans, 0u);
  EXPECT_EQ(vec3(layer.tables().instances[slot].world_from_object[3]), vec3(2, 3, -1));
  EXPECT_NEAR(layer.tables().instances[slot].world_bounds_min.y, 2.0f, 1e-5f);
}

TEST(SceneLayer, OneDeformedMeshIsOneRefitOfItsOwnVertices) {
  World w;
  SceneLayer layer;
  Ticker tick;
  tick(w.reg, layer);
  w.reg.get<Animation>(w.blob).speed = 1.0f;
  const SceneDelta& d = tick(w.reg, layer, 0.5);
  const std::uint32_t slot = *layer.instance_of(w.blob);
  ASSERT_EQ(d.instances_deformed.size(), 1u);
  EXPECT_EQ(d.instances_deformed[0], slot);
  EXPECT_TRUE(d.instances_moved.empty());
  EXPECT_FALSE(d.static_rebuilt);
  const Mesh& mesh = w.reg.get<Mesh>(w.blob);
  EXPECT_EQ(layer.stats().vertices_written, mesh.deformed_positions.size()); // only the blob's
  const gpu::GpuMesh& record = layer.tables().meshes[layer.tables().instances[slot].mesh];
  for (std::size_t i = 0; i < mesh.deformed_positions.size(); ++i)
    EXPECT_EQ(layer.tables().positions[record.first_vertex + i], mesh.deformed_positions[i]);
  // The shared sphere the ball uses is untouched.
  const gpu::GpuMesh& shared =
      layer.tables().meshes[layer.tables().instances[*layer.instance_of(w.ball)].mesh];
  EXPECT_EQ(layer.tables().positions[shared.first_vertex],
            w.reg.get<Mesh>(w.ball).geometry->positions[0]);
}

/// A normal track (BART's tpa normals) gives a deforming mesh its own vertex normals: sampled
/// with its vertices, rewritten with them, carried along by a relayout. Without one it has none
/// (shading takes the geometric normal), and a track given again gets a range again.
TEST(SceneLayer, ADeformedMeshWithANormalTrackCarriesItsSampledNormals) {
  World w;
  const TriangleMesh& sphere = *w.reg.get<Mesh>(w.blob).geometry;
  ASSERT_EQ(sphere.normals.size(), sphere.positions.size());
  Keyframes<std::vector<vec3>> track;
  track.times = {0.0f, 1.0f};
  std::vector<vec3> stretched = sphere.normals; // the normals of the sphere stretched by 2 in y
  for (vec3& n : stretched) n = glm::normalize(vec3(n.x, 0.5f * n.y, n.z));
  track.values = {sphere.normals, stretched};
  w.reg.get<Animation>(w.blob).normals = track;
  SceneLayer layer;
  Ticker tick;
  const auto normals_of = [&]() -> std::vector<vec3> {
    const SceneTables& t = layer.tables();
    const gpu::GpuInstance& inst = t.instances[*layer.instance_of(w.blob)];
    EXPECT_NE(inst.flags & gpu::kInstanceSmooth, 0u);
    const gpu::GpuMesh& record = t.meshes[inst.mesh];
    if (record.first_normal == gpu::kNoIndex) return {};
    const auto first = t.normals.begin() + record.first_normal;
    return {first, first + record.vertex_count};
  };
  const Mesh& mesh = w.reg.get<Mesh>(w.blob);
  tick(w.reg, layer);
  const std::vector<vec3> first = normals_of();
  EXPECT_EQ(first, mesh.deformed_normals);
  ASSERT_EQ(first.size(), sphere.normals.size());
  for (std::size_t i = 0; i < first.size(); ++i)
    EXPECT_LT(glm::distance(first[i], sphere.normals[i]), 1e-6f) << "key 0's normal " << i;

  w.reg.get<Animation>(w.blob).speed = 1.0f;
  ASSERT_EQ(tick(w.reg, layer, 0.5).instances_deformed.size(), 1u);
  const std::vector<vec3> half = normals_of();
  ASSERT_EQ(half.size(), sphere.normals.size());
  std::size_t turned = 0;
  for (std::size_t i = 0; i < half.size(); ++i) {
    const vec3 expected = glm::normalize(glm::mix(sphere.normals[i], stretched[i], 0.5f));
    EXPECT_LT(glm::distance(half[i], expected), 1e-6f) << "vertex " << i;
    EXPECT_NEAR(glm::length(half[i]), 1.0f, 1e-6f);
    turned += glm::distance(half[i], sphere.normals[i]) > 1e-3f ? 1u : 0u;
  }
  EXPECT_GT(turned, half.size() / 2) << "the normals follow the stretch";

  // A relayout (the static set baked again; dt 0: nothing deforms) moves them with the vertices.
  w.reg.get<Transform>(w.ground).translation.y = -1.0f;
  EXPECT_TRUE(tick(w.reg, layer, 0.0).static_rebuilt);
  EXPECT_EQ(layer.stats().relayouts, 1u);
  EXPECT_EQ(normals_of(), half);

  w.reg.get<Animation>(w.blob).normals = {};
  ASSERT_EQ(tick(w.reg, layer, 0.25).instances_deformed.size(), 1u);
  EXPECT_TRUE(mesh.deformed_normals.empty());
  EXPECT_TRUE(normals_of().empty()) << "no normals to match the vertices: geometric normals";

  w.reg.get<Animation>(w.blob).normals = track;
  ASSERT_EQ(tick(w.reg, layer, 0.1).instances_deformed.size(), 1u);
  EXPECT_FALSE(mesh.deformed_normals.empty());
  EXPECT_EQ(normals_of(), mesh.deformed_normals);
}

/// A normal track taken away and given back, 1,000 times: each return appends a fresh range, and
/// the dropped ones are compacted away once they outnumber the live normals (and 64 Ki), so the
/// pool stays bounded; before, it grew by the mesh's vertex count every cycle until some other
/// relayout.
TEST(SceneLayer, ANormalTrackThatComesAndGoesDoesNotGrowThePoolWithoutBound) {
  World w;
  const TriangleMesh& sphere = *w.reg.get<Mesh>(w.blob).geometry;
  Keyframes<std::vector<vec3>> track;
  track.times = {0.0f, 1.0f};
  track.values = {sphere.normals, sphere.normals};
  Animation& anim = w.reg.get<Animation>(w.blob);
  anim.normals = track;
  anim.speed = 1.0f;
  SceneLayer layer;
  Ticker tick;
  tick(w.reg, layer);
  const std::size_t initial = layer.tables().normals.size();
  const std::size_t v = sphere.positions.size();
  constexpr int kCycles = 1000;
  ASSERT_GT(kCycles * v, std::size_t(1) << 17) << "enough cycles to need a compaction";
  std::size_t largest = 0;
  std::uint32_t relayouts = 0; // the stats are the last sync's
  for (int i = 0; i < kCycles; ++i) {
    w.reg.get<Animation>(w.blob).normals = {};
    ASSERT_EQ(tick(w.reg, layer, 0.001).instances_deformed.size(), 1u);
    relayouts += layer.stats().relayouts;
    w.reg.get<Animation>(w.blob).normals = track;
    ASSERT_EQ(tick(w.reg, layer, 0.001).instances_deformed.size(), 1u);
    relayouts += layer.stats().relayouts;
    largest = std::max(largest, layer.tables().normals.size());
  }
  EXPECT_LE(largest, initial + (std::size_t(1) << 16) + v);
  EXPECT_GE(relayouts, 1u);
  const SceneTables& t = layer.tables();
  const gpu::GpuMesh& record = t.meshes[t.instances[*layer.instance_of(w.blob)].mesh];
  ASSERT_NE(record.first_normal, gpu::kNoIndex);
  const std::vector<vec3>& sampled = w.reg.get<Mesh>(w.blob).deformed_normals;
  ASSERT_EQ(sampled.size(), v);
  for (std::size_t i = 0; i < v; ++i) EXPECT_EQ(t.normals[record.first_normal + i], sampled[i]);
}

TEST(SceneLayer, AMovedStaticEntityIsBakedAgainWhereItNowIs) {
  World w;
  SceneLayer layer;
  Ticker tick;
  tick(w.reg, layer);
  w.reg.get<Transform>(w.ground).translation.y = -1.0f;
  const SceneDelta& d = tick(w.reg, layer);
  EXPECT_TRUE(d.static_rebuilt);
  EXPECT_EQ(layer.stats().static_bakes, 1u);
  const SceneTables& t = layer.tables();
  const gpu::GpuMesh& ground = t.meshes[t.instances[*layer.instance_of(w.ground)].mesh];
  EXPECT_EQ(t.positions[ground.first_vertex].y, -1.0f);
  EXPECT_TRUE(tick(w.reg, layer).empty());
}

TEST(SceneLayer, AddedAndDestroyedEntitiesAreAddedAndRemoved) {
  World w;
  SceneLayer layer;
  Ticker tick;
  tick(w.reg, layer);
  const std::uint32_t twin_slot = *layer.instance_of(w.twin);
  const std::uint32_t ball_slot = *layer.instance_of(w.ball);
  w.reg.destroy(w.twin);
  const SceneDelta& d1 = tick(w.reg, layer);
  EXPECT_EQ(d1.instances_removed, std::vector<std::uint32_t>{twin_slot});
  EXPECT_TRUE(d1.meshes_removed.empty()); // the ball still uses the shared sphere
  EXPECT_FALSE(d1.static_rebuilt);
  EXPECT_FALSE(layer.tables().live(twin_slot));
  w.reg.destroy(w.ball);
  const SceneDelta& d2 = tick(w.reg, layer);
  EXPECT_EQ(d2.instances_removed, std::vector<std::uint32_t>{ball_slot});
  EXPECT_EQ(d2.meshes_removed.size(), 1u); // its last user is gone
  // A new free entity takes a freed slot and brings its mesh.
  const ecs::Entity cone =
      test::add_mesh(w.reg, test::primitive("cone", 0.5f), test::at(vec3(0, 0, -3)), Material{},
                     Kinematics::Type::Free);
  const SceneDelta& d3 = tick(w.reg, layer);
  ASSERT_EQ(d3.instances_added.size(), 1u);
  EXPECT_EQ(d3.instances_added[0], *layer.instance_of(cone));
  EXPECT_EQ(d3.meshes_added.size(), 1u);
  EXPECT_TRUE(d3.instances_added[0] == twin_slot || d3.instances_added[0] == ball_slot);
  // A new static entity changes the static set.
  test::add_mesh(w.reg, test::primitive("box", 1.0f), test::at(vec3(6, 0.5f, 6)));
  EXPECT_TRUE(tick(w.reg, layer).static_rebuilt);
  EXPECT_EQ(layer.tables().static_instances.size(), 3u);
}

TEST(SceneLayer, MaterialEditsAnnouncedWithPatchReachTheTable) {
  World w;
  SceneLayer layer;
  Ticker tick;
  tick(w.reg, layer);
  const std::uint32_t slot = *layer.instance_of(w.ball);
  w.reg.patch<Material>(w.ball, [](Material& m) { m.reflectivity = 0.75f; });
  const SceneDelta& d = tick(w.reg, layer);
  EXPECT_TRUE(d.materials_changed);
  EXPECT_EQ(layer.tables().materials[slot].reflectivity, 0.75f);
  EXPECT_FALSE(d.static_rebuilt);
  EXPECT_TRUE(d.instances_moved.empty());
  EXPECT_FALSE(tick(w.reg, layer).materials_changed);
}

TEST(SceneLayer, LightChangesAreReported) {
  World w;
  SceneLayer layer;
  Ticker tick;
  tick(w.reg, layer);
  w.reg.get<Transform>(w.lamp).translation.x = 1.0f;
  const SceneDelta& d = tick(w.reg, layer);
  EXPECT_TRUE(d.lights_changed);
  EXPECT_EQ(layer.tables().lights.at(0).position.x, 1.0f);
  EXPECT_FALSE(d.static_rebuilt);
}

TEST(SceneLayer, AnAnimatedEntityWithoutKinematicsIsDynamic) {
  ecs::Registry reg;
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e);
  reg.emplace<Mesh>(
      e, Mesh{std::make_shared<const TriangleMesh>(make_primitive(test::primitive("box"), "test")),
              {},
              {},
              0});
  Animation anim;
  anim.translation.times = {0.0f, 1.0f};
  anim.translation.values = {vec3(0), vec3(1, 0, 0)};
  reg.emplace<Animation>(e, anim);
  SceneLayer layer;
  Ticker tick;
  tick(reg, layer);
  EXPECT_TRUE(layer.tables().static_instances.empty());
  EXPECT_EQ(layer.tables().instances[*layer.instance_of(e)].kinematics,
            gpu::kKinematicsHierarchical);
  EXPECT_EQ(tick(reg, layer).instances_moved.size(), 1u);
}

TEST(SceneLayer, CompactionKeepsEveryRecordPointingAtItsOwnData) {
  // Many distinct meshes come and go: the pools fill with garbage until a relayout compacts them,
  // after which every live instance still reads its own vertices and triangles.
  World w;
  SceneLayer layer;
  Ticker tick;
  tick(w.reg, layer);
  std::vector<ecs::Entity> added;
  std::uint32_t relayouts = 0;
  for (int round = 0; round < 12; ++round) {
    for (int k = 0; k < 4; ++k)
      added.push_back(test::add_mesh(
          w.reg, test::primitive("sphere", 0.2f + 0.01f * float(round * 4 + k), vec3(1), 96, 48),
          test::at(vec3(float(k), 5, float(round))), Material{}, Kinematics::Type::Free));
    tick(w.reg, layer);
    relayouts += layer.stats().relayouts;
    // Keep the last four; destroy the rest.
    while (added.size() > 4) {
      w.reg.destroy(added.front());
      added.erase(added.begin());
    }
    tick(w.reg, layer);
    relayouts += layer.stats().relayouts;
  }
  EXPECT_GT(relayouts, 0u) << "the test must exercise a compaction";
  const SceneTables& t = layer.tables();
  for (const ecs::Entity e : {w.ball, w.twin, w.pillar, w.ground, added[0], added[3]}) {
    const std::uint32_t slot = *layer.instance_of(e);
    const gpu::GpuInstance& inst = t.instances[slot];
    const TriangleMesh& source = *w.reg.get<Mesh>(e).geometry;
    const gpu::GpuMesh& record = t.meshes[inst.mesh];
    ASSERT_EQ(record.vertex_count, source.positions.size());
    ASSERT_EQ(record.triangle_count, source.triangles.size());
    const mat4 m = (inst.flags & gpu::kInstanceIdentity)
                       ? mat4(w.reg.get<WorldTransform>(e).world_from_object)
                       : mat4(1.0f);
    for (std::size_t i = 0; i < source.positions.size(); i += 7)
      EXPECT_EQ(t.positions[record.first_vertex + i], vec3(m * vec4(source.positions[i], 1.0f)));
    for (std::size_t i = 0; i < source.triangles.size(); i += 5)
      EXPECT_EQ(t.triangles[record.first_triangle + i], source.triangles[i]);
  }
  // What is left unused is bounded by what is used (or the 64k-vertex floor), as documented.
  std::size_t live = 0;
  for (const gpu::GpuMesh& record : t.meshes)
    if (record.first_vertex != gpu::kNoIndex) live += record.vertex_count;
  EXPECT_LE(t.positions.size() - live, std::max<std::size_t>(live, 1u << 16));
}

} // namespace
} // namespace specula
