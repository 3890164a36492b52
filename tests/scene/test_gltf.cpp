// glTF loader tests. Files under tests/data/gltf/ come from make_test_files.py there; the numbers
// compared below are the ones that script writes. Expected matrices are built here with GLM's
// translate/rotate/scale, independently of the loader's own TRS code.

#include "specula/core/error.h"
#include "specula/core/log.h"
#include "specula/scene/animation_sampling.h"
#include "specula/scene/components.h"
#include "specula/scene/gltf_loader.h"
#include "specula/scene/hierarchy.h"
#include "specula/scene/scene.h"

#include <glm/gtc/matrix_transform.hpp>
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

namespace fs = std::filesystem;
using namespace specula;

namespace {

const fs::path kData = fs::path(SPECULA_TEST_DATA_DIR) / "gltf";
const fs::path kAssimp = "/usr/share/assimp/models/glTF2";

/// The entity named `name` (null when there is none; the test files use unique names).
ecs::Entity find(ecs::Registry& reg, const std::string& name) {
  ecs::Entity found = ecs::null_entity;
  reg.view<Name>().each([&](ecs::Entity e, const Name& n) {
    if (n.value == name) found = e;
  });
  return found;
}

/// Children of `parent`, in creation order.
std::vector<ecs::Entity> children_of(ecs::Registry& reg, ecs::Entity parent) {
  std::vector<ecs::Entity> out;
  reg.view<Parent>().each([&](ecs::Entity e, const Parent& p) {
    if (p.entity == parent) out.push_back(e);
  });
  std::sort(out.begin(), out.end(), [](ecs::Entity a, ecs::Entity b) { return a.index < b.index; });
  return out;
}

void expect_near(const vec3& actual, const vec3& expected, float tolerance = 1e-5f) {
  EXPECT_NEAR(actual.x, expected.x, tolerance);
  EXPECT_NEAR(actual.y, expected.y, tolerance);
  EXPECT_NEAR(actual.z, expected.z, tolerance);
}

void expect_near(const mat4& actual, const mat4& expected, float tolerance = 1e-5f) {
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r)
      EXPECT_NEAR(actual[c][r], expected[c][r], tolerance) << "column " << c << " row " << r;
}

/// Same rotation (q and −q are the same rotation).
void expect_same_rotation(const quat& actual, const quat& expected) {
  EXPECT_NEAR(std::abs(glm::dot(actual, expected)), 1.0f, 1e-5f);
}

const mat4 kIdentity(1.0f);
// hierarchy.gltf: root = T(1,2,3)·Ry(90°)·S(2); child (a matrix) = T(0,1,0)·Rx(90°)·S(0.5).
const mat4 kWorldFromRoot = glm::scale(
    glm::rotate(glm::translate(kIdentity, vec3(1, 2, 3)), glm::radians(90.0f), vec3(0, 1, 0)),
    vec3(2.0f));
const mat4 kRootFromChild = glm::scale(
    glm::rotate(glm::translate(kIdentity, vec3(0, 1, 0)), glm::radians(90.0f), vec3(1, 0, 0)),
    vec3(0.5f));

class GltfHierarchy : public ::testing::Test {
protected:
  void SetUp() override { scene_ = load_gltf_scene(kData / "hierarchy.gltf"); }
  ecs::Registry& reg() { return scene_.registry; }
  Scene scene_;
};

} // namespace

// --- Hierarchy and transforms ----------------------------------------------------------------

TEST_F(GltfHierarchy, ParentLinksFollowTheNodeTreeOfTheDefaultScene) {
  const ecs::Entity root = find(reg(), "root");
  const ecs::Entity child = find(reg(), "child");
  const ecs::Entity unnamed = find(reg(), "node 2"); // unnamed nodes are "node N"
  ASSERT_FALSE(root.is_null());
  ASSERT_FALSE(child.is_null());
  ASSERT_FALSE(unnamed.is_null());
  EXPECT_FALSE(reg().has<Parent>(root));
  EXPECT_EQ(reg().get<Parent>(child).entity, root);
  EXPECT_EQ(reg().get<Parent>(unnamed).entity, child);
  EXPECT_EQ(reg().get<Parent>(find(reg(), "camera")).entity, root);
  EXPECT_EQ(reg().get<Parent>(find(reg(), "spot")).entity, root);
  EXPECT_FALSE(reg().has<Parent>(find(reg(), "sun")));
  // scenes[1] holds "other scene"; `scene` selects scenes[0].
  EXPECT_TRUE(find(reg(), "other scene").is_null());
  // 8 nodes, plus 2 material parts of node 2's mesh.
  EXPECT_EQ(reg().alive(), 10u);
  // Every entity has a Transform. The loader leaves world transforms and kinematics to
  // load_scene.
  EXPECT_EQ(reg().count<Transform>(), reg().alive());
  EXPECT_EQ(reg().count<WorldTransform>(), 0u);
  EXPECT_EQ(reg().count<Kinematics>(), 0u);
}

TEST_F(GltfHierarchy, WorldTransformsMatchMatricesComputedFromTheFile) {
  update_world_transforms(reg(), 0, "hierarchy.gltf");
  const mat4 world_from_child = kWorldFromRoot * kRootFromChild;
  const mat4 world_from_node2 = world_from_child * glm::translate(kIdentity, vec3(0, 0, -1));
  expect_near(reg().get<WorldTransform>(find(reg(), "root")).world_from_object, kWorldFromRoot);
  expect_near(reg().get<WorldTransform>(find(reg(), "child")).world_from_object, world_from_child);
  expect_near(reg().get<WorldTransform>(find(reg(), "node 2")).world_from_object, world_from_node2);
  // Material parts sit at their node's origin.
  for (const ecs::Entity part : children_of(reg(), find(reg(), "node 2")))
    expect_near(reg().get<WorldTransform>(part).world_from_object, world_from_node2);
}

TEST_F(GltfHierarchy, MatrixNodeIsDecomposedIntoTranslationRotationScale) {
  const Transform& t = reg().get<Transform>(find(reg(), "child"));
  expect_near(t.translation, vec3(0, 1, 0));
  expect_near(t.scale, vec3(0.5f));
  expect_same_rotation(t.rotation, glm::angleAxis(glm::radians(90.0f), vec3(1, 0, 0)));
  expect_near(t.parent_from_local(), kRootFromChild);
}

TEST_F(GltfHierarchy, NodesUsingOneMeshShareItsGeometry) {
  const Mesh& a = reg().get<Mesh>(find(reg(), "root"));
  const Mesh& b = reg().get<Mesh>(find(reg(), "child"));
  ASSERT_TRUE(a.geometry);
  EXPECT_EQ(a.geometry.get(), b.geometry.get());
  EXPECT_EQ(a.geometry->triangle_count(), 2u);
  EXPECT_EQ(a.source.kind, MeshSource::Kind::File);
  EXPECT_EQ(a.source.path, "hierarchy.gltf");
  EXPECT_EQ(a.source.gltf_mesh, 0);
  // The File source must rebuild the same geometry.
  const TriangleMesh again = load_gltf_mesh(kData / "hierarchy.gltf", 0);
  EXPECT_EQ(again.positions, a.geometry->positions);
  EXPECT_EQ(again.triangles, a.geometry->triangles);
  EXPECT_EQ(again.normals, a.geometry->normals);
}

TEST_F(GltfHierarchy, MeshWithSeveralMaterialsGetsOneChildEntityPerMaterial) {
  const ecs::Entity node = find(reg(), "node 2");
  EXPECT_FALSE(reg().has<Mesh>(node));
  const std::vector<ecs::Entity> parts = children_of(reg(), node);
  ASSERT_EQ(parts.size(), 2u);
  const Transform identity;
  for (const ecs::Entity part : parts) {
    EXPECT_EQ(reg().get<Transform>(part), identity);
    ASSERT_TRUE(reg().has<Mesh>(part) && reg().has<Material>(part));
    const Mesh& mesh = reg().get<Mesh>(part);
    // A subset of a glTF mesh cannot be named by a mesh index: the geometry is inline.
    EXPECT_EQ(mesh.source.kind, MeshSource::Kind::Inline);
    // The file has no normals: they are computed (the triangles face +Z).
    ASSERT_EQ(mesh.geometry->normals.size(), mesh.geometry->vertex_count());
    for (const vec3& n : mesh.geometry->normals) expect_near(n, vec3(0, 0, 1));
  }
  // First-use order: glass (primitives 0 and 2 merged), then glow (primitive 1).
  EXPECT_EQ(reg().get<Material>(parts[0]).transmission, 0.9f);
  EXPECT_EQ(reg().get<Mesh>(parts[0]).geometry->triangle_count(), 2u);
  EXPECT_EQ(reg().get<Mesh>(parts[1]).geometry->triangle_count(), 1u);
  EXPECT_GT(reg().get<Material>(parts[1]).emission.x, 0.0f);
  // Merging shifts the second primitive's indices past the first one's vertices.
  const TriangleMesh& glass = *reg().get<Mesh>(parts[0]).geometry;
  EXPECT_EQ(glass.triangles[1], uvec3(3, 4, 5));
  expect_near(glass.positions[3], vec3(2, 0, 0));
}

// --- Materials, cameras, lights --------------------------------------------------------------

TEST_F(GltfHierarchy, PbrFactorsMapToMaterial) {
  const Material& mirror = reg().get<Material>(find(reg(), "root"));
  expect_near(mirror.base_color, vec3(0.9f));
  EXPECT_FLOAT_EQ(mirror.reflectivity, 1.0f); // metallic 1 × (1 − roughness 0)
  EXPECT_FLOAT_EQ(mirror.transmission, 0.0f);
  EXPECT_FLOAT_EQ(mirror.roughness, 0.0f);
  EXPECT_TRUE(mirror.is_reflective());

  const std::vector<ecs::Entity> parts = children_of(reg(), find(reg(), "node 2"));
  ASSERT_EQ(parts.size(), 2u);
  const Material& glass = reg().get<Material>(parts[0]);
  EXPECT_FLOAT_EQ(glass.transmission, 0.9f); // metallic 0: the full transmission factor
  EXPECT_FLOAT_EQ(glass.ior, 1.33f);
  EXPECT_FLOAT_EQ(glass.reflectivity, 0.0f);
  EXPECT_TRUE(glass.is_refractive());

  const Material& glow = reg().get<Material>(parts[1]);
  expect_near(glow.base_color, vec3(0.2f, 0.4f, 0.6f));
  EXPECT_FLOAT_EQ(glow.reflectivity, 0.25f);          // 0.5 × (1 − 0.5)
  expect_near(glow.emission, vec3(4.0f, 2.0f, 1.0f)); // emissiveFactor × strength 4
  EXPECT_FLOAT_EQ(glow.roughness, 0.5f);
  EXPECT_FLOAT_EQ(glow.ior, 1.5f); // no KHR_materials_ior: the glTF default
  for (const Material* m : {&mirror, &glass, &glow})
    EXPECT_LE(m->reflectivity + m->transmission, 1.0f);
}

TEST_F(GltfHierarchy, PerspectiveCameraSitsAtNodeOriginLookingAlongMinusZ) {
  // The orthographic camera node is kept, without a Camera.
  EXPECT_EQ(reg().count<Camera>(), 1u);
  EXPECT_FALSE(find(reg(), "ortho").is_null());
  EXPECT_FALSE(reg().has<Camera>(find(reg(), "ortho")));

  const Camera& camera = reg().get<Camera>(find(reg(), "camera"));
  const mat4 world_from_camera = kWorldFromRoot * glm::translate(kIdentity, vec3(0, 0, 5));
  const vec3 position = vec3(world_from_camera * vec4(0, 0, 0, 1));
  const vec3 forward = glm::normalize(vec3(world_from_camera * vec4(0, 0, -1, 0)));
  expect_near(camera.position, position);
  expect_near(camera.position, vec3(11, 2, 3)); // the same, by hand: Ry(90°) turns +Z to +X
  expect_near(glm::normalize(camera.look_at - camera.position), forward);
  expect_near(camera.up, vec3(0, 1, 0));
  EXPECT_FLOAT_EQ(camera.vertical_fov, 0.8f);
  EXPECT_FLOAT_EQ(camera.aspect, 1.5f);
}

TEST_F(GltfHierarchy, PunctualLightsKeepTypeColorIntensityAndCones) {
  EXPECT_EQ(reg().count<Light>(), 3u);
  const Light& sun = reg().get<Light>(find(reg(), "sun"));
  EXPECT_EQ(sun.type, Light::Type::Directional);
  EXPECT_FLOAT_EQ(sun.intensity, 3.0f);
  expect_near(sun.color, vec3(1.0f, 0.9f, 0.8f));
  // Directional lights point along the node's −Z: rotated −90° about X, that is straight down.
  const Transform& sun_t = reg().get<Transform>(find(reg(), "sun"));
  expect_near(sun_t.rotation * vec3(0, 0, -1), vec3(0, -1, 0));

  const Light& spot = reg().get<Light>(find(reg(), "spot"));
  EXPECT_EQ(spot.type, Light::Type::Spot);
  EXPECT_FLOAT_EQ(spot.intensity, 50.0f);
  EXPECT_FLOAT_EQ(spot.range, 10.0f);
  EXPECT_FLOAT_EQ(spot.inner_cone, 0.2f);
  EXPECT_FLOAT_EQ(spot.outer_cone, 0.6f);

  const Light& lamp = reg().get<Light>(find(reg(), "lamp"));
  EXPECT_EQ(lamp.type, Light::Type::Point);
  EXPECT_FLOAT_EQ(lamp.intensity, 100.0f);
  expect_near(lamp.color, vec3(1.0f));
  EXPECT_FLOAT_EQ(lamp.range, 0.0f); // unlimited
}

// --- Animation --------------------------------------------------------------------------------

TEST(GltfAnimation, TracksSampledAtKeyTimesGiveTheKeys) {
  Scene scene = load_gltf_scene(kData / "animated.gltf");
  ecs::Registry& reg = scene.registry;
  const Animation& a = reg.get<Animation>(find(reg, "mover"));

  // LINEAR translation; the second clip's translation of the same node is ignored.
  ASSERT_EQ(a.translation.times, (std::vector<float>{0, 1, 2}));
  EXPECT_EQ(a.translation.interpolation, Interpolation::Linear);
  const vec3 translations[] = {{0, 0, 0}, {1, 0, 0}, {1, 2, 0}};
  for (int k = 0; k < 3; ++k)
    expect_near(sample(a.translation, a.translation.times[std::size_t(k)]), translations[k]);
  expect_near(sample(a.translation, 0.5f), vec3(0.5f, 0, 0));

  // STEP rotation holds the previous key.
  EXPECT_EQ(a.rotation.interpolation, Interpolation::Step);
  const quat quarter_turn = glm::angleAxis(glm::radians(90.0f), vec3(0, 0, 1));
  expect_same_rotation(sample(a.rotation, 0.0f), quat(1, 0, 0, 0));
  expect_same_rotation(sample(a.rotation, 0.9f), quat(1, 0, 0, 0));
  expect_same_rotation(sample(a.rotation, 1.0f), quarter_turn);

  // CUBICSPLINE keeps the values (the tangents in the file are 9s) and samples linearly.
  EXPECT_EQ(a.scale.interpolation, Interpolation::Linear);
  ASSERT_EQ(a.scale.values.size(), 2u);
  expect_near(sample(a.scale, 0.0f), vec3(1.0f));
  expect_near(sample(a.scale, 1.0f), vec3(2.0f));
  expect_near(sample(a.scale, 0.5f), vec3(1.5f));
  EXPECT_FLOAT_EQ(a.duration(), 2.0f);
}

TEST(GltfAnimation, KinematicsFollowWhatMoves) {
  Scene scene = load_scene(kData / "animated.gltf"); // which infers them
  ecs::Registry& reg = scene.registry;
  const auto type = [&](const char* name) { return reg.get<Kinematics>(find(reg, name)).type; };
  EXPECT_EQ(type("mover"), Kinematics::Type::Hierarchical);
  EXPECT_EQ(type("rider"), Kinematics::Type::Hierarchical); // child of an animated node
  EXPECT_EQ(type("still"), Kinematics::Type::Static);
  EXPECT_EQ(type("blob"), Kinematics::Type::Free); // morph animation deforms it
  EXPECT_EQ(type("posed"), Kinematics::Type::Static);
  EXPECT_FALSE(reg.has<Animation>(find(reg, "rider")));
}

TEST(GltfAnimation, MorphWeightsGiveBasePlusWeightedTargets) {
  Scene scene = load_gltf_scene(kData / "animated.gltf");
  ecs::Registry& reg = scene.registry;
  // Triangle (0,0,0) (1,0,0) (0,1,0); target 0 moves every vertex by +Z, target 1 vertex 0 by +X.
  const std::vector<vec3> base = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  const auto expected = [&](float w0, float w1) {
    std::vector<vec3> p = base;
    for (vec3& v : p) v.z += w0;
    p[0].x += w1;
    return p;
  };
  const ecs::Entity blob = find(reg, "blob");
  const Animation& a = reg.get<Animation>(blob);
  ASSERT_EQ(a.vertices.times, (std::vector<float>{0, 1, 2}));
  const float weights[3][2] = {{0, 0}, {1, 0}, {0.5f, 1}};
  std::vector<vec3> sampled;
  for (std::size_t k = 0; k < 3; ++k) {
    sample(a.vertices, a.vertices.times[k], sampled);
    const std::vector<vec3> want = expected(weights[k][0], weights[k][1]);
    ASSERT_EQ(sampled.size(), want.size());
    for (std::size_t v = 0; v < want.size(); ++v) expect_near(sampled[v], want[v]);
  }
  // Linear in the weights between keys.
  sample(a.vertices, 1.5f, sampled);
  const std::vector<vec3> halfway = expected(0.75f, 0.5f);
  for (std::size_t v = 0; v < halfway.size(); ++v) expect_near(sampled[v], halfway[v]);

  // The shared geometry uses the mesh's default weights (0, 0) and can be named by index...
  const Mesh& blob_mesh = reg.get<Mesh>(blob);
  EXPECT_EQ(blob_mesh.geometry->positions, base);
  EXPECT_EQ(blob_mesh.source.kind, MeshSource::Kind::File);
  EXPECT_EQ(blob_mesh.source.gltf_mesh, 1);
  // ...while a node with its own weights (1, 0) gets its own, inline geometry.
  const Mesh& posed = reg.get<Mesh>(find(reg, "posed"));
  EXPECT_NE(posed.geometry.get(), blob_mesh.geometry.get());
  EXPECT_EQ(posed.source.kind, MeshSource::Kind::Inline);
  const std::vector<vec3> posed_want = expected(1, 0);
  for (std::size_t v = 0; v < posed_want.size(); ++v)
    expect_near(posed.geometry->positions[v], posed_want[v]);
}

TEST(GltfAnimation, NormalTargetsMorphTheNormalsAsTheWeightsMove) {
  Scene scene = load_gltf_scene(kData / "animated.gltf");
  ecs::Registry& reg = scene.registry;
  // Normals +Z; target 0 adds (0, 1, -1) to each, target 1 has no NORMAL: with target 0's
  // weight w the normal is (0, w, 1 - w), normalised (glTF: NORMAL targets are displacements).
  const auto normal = [](float w) { return glm::normalize(vec3(0, w, 1 - w)); };
  const Animation& a = reg.get<Animation>(find(reg, "bender"));
  ASSERT_EQ(a.normals.times, a.vertices.times);
  EXPECT_EQ(a.normals.interpolation, a.vertices.interpolation);
  // Weights (0, 0), (1, 0), (0.5, 1) at 0, 1, 2 s: at each key time and between keys, the
  // sampled normal is the one of the interpolated weights.
  const std::pair<float, float> at[] = {
      {0.0f, 0.0f}, {0.5f, 0.5f}, {1.0f, 1.0f}, {1.5f, 0.75f}, {2.0f, 0.5f}};
  std::vector<vec3> sampled;
  for (const auto& [t, w] : at) {
    SCOPED_TRACE(t);
    sample_normals(a.normals, t, sampled);
    ASSERT_EQ(sampled.size(), 3u);
    for (const vec3& n : sampled) expect_near(n, normal(w));
  }
  // A node posed with weights (0.5, 0) gets morphed unit normals in its own geometry.
  for (const vec3& n : reg.get<Mesh>(find(reg, "leaning")).geometry->normals)
    expect_near(n, normal(0.5f));
  // Without NORMAL there is no normal track: face normals follow the moving vertices.
  EXPECT_TRUE(reg.get<Animation>(find(reg, "blob")).normals.empty());
}

// --- Accessors and primitive modes -----------------------------------------------------------

TEST(GltfAccessors, SparseValuesReplaceTheBaseOrZeros) {
  Scene scene = load_gltf_scene(kData / "sparse.gltf");
  ecs::Registry& reg = scene.registry;
  const TriangleMesh& replaced = *reg.get<Mesh>(find(reg, "node 0")).geometry;
  expect_near(replaced.positions[0], vec3(0, 0, 0));
  expect_near(replaced.positions[1], vec3(5, 5, 5));
  expect_near(replaced.positions[2], vec3(0, 1, 0));
  // A morph target without a bufferView: zeros except the sparse vertex 2 (+3 Z), weight 1.
  const TriangleMesh& morphed = *reg.get<Mesh>(find(reg, "node 1")).geometry;
  expect_near(morphed.positions[0], vec3(0, 0, 0));
  expect_near(morphed.positions[1], vec3(2, 0, 0));
  expect_near(morphed.positions[2], vec3(0, 2, 3));
}

TEST(GltfMesh, StripsAndFansBecomeTriangleListsAndPointsAreSkipped) {
  const TriangleMesh mesh = load_gltf_mesh(kData / "modes.gltf", 0);
  // Strip of 4 vertices: 2 triangles; fan of 5: 3 triangles; the point list adds nothing.
  ASSERT_EQ(mesh.triangle_count(), 5u);
  EXPECT_EQ(mesh.vertex_count(), 9u);
  EXPECT_NO_THROW(mesh.validate("modes.gltf"));
  // Every triangle keeps the counter-clockwise winding (faces +Z), as the glTF spec orders them.
  for (const uvec3& t : mesh.triangles) {
    const vec3 n = glm::cross(mesh.positions[t.y] - mesh.positions[t.x],
                              mesh.positions[t.z] - mesh.positions[t.x]);
    EXPECT_GT(n.z, 0.0f);
  }
  // The fan's positions are normalized shorts (KHR_mesh_quantization): 16384 / 32767.
  EXPECT_NEAR(mesh.positions[5].x, 16384.0f / 32767.0f, 1e-6f);
}

TEST(GltfMesh, MeshIndexOutOfRangeIsAnError) {
  const fs::path path = kData / "hierarchy.gltf";
  for (const int index : {-1, 2, 1000}) {
    try {
      (void)load_gltf_mesh(path, index);
      ADD_FAILURE() << "mesh index " << index << " loaded";
    } catch (const Error& e) {
      EXPECT_EQ(e.file(), path.string());
      EXPECT_NE(std::string(e.what()).find("out of range"), std::string::npos) << e.what();
    }
  }
}

// --- Through load_scene, and the sample scene --------------------------------------------------

TEST(GltfLoadScene, BinaryFileLoadsWithWorldTransformsAndDefaults) {
  Scene scene = load_scene(kData / "box.glb");
  ecs::Registry& reg = scene.registry;
  EXPECT_EQ(scene.source, kData / "box.glb");
  EXPECT_EQ(reg.count<Mesh>(), 1u);
  // Every entity with a Transform got its world transform.
  reg.view<Transform>().each(
      [&](ecs::Entity e, const Transform&) { EXPECT_TRUE(reg.has<WorldTransform>(e)); });
  // The file's camera is kept (no default camera); the missing light is added as a default.
  ASSERT_EQ(reg.count<Camera>(), 1u);
  const ecs::Entity eye = find(reg, "eye");
  ASSERT_TRUE(reg.has<Camera>(eye));
  EXPECT_FALSE(reg.has<DefaultTag>(eye));
  expect_near(reg.get<Camera>(eye).position, vec3(0, 0, 4));
  EXPECT_FLOAT_EQ(reg.get<Camera>(eye).aspect, 1.0f); // no aspectRatio: settings 1024 × 1024
  ASSERT_EQ(reg.count<Light>(), 1u);
  reg.view<Light>().each([&](ecs::Entity e, const Light&) { EXPECT_TRUE(reg.has<DefaultTag>(e)); });
}

TEST(GltfSample, SmallSceneLoadsWithExpectedCounts) {
  const fs::path path = fs::path(SPECULA_SOURCE_DIR) / "samples/scenes/small_scene.gltf";
  Scene scene = load_scene(path);
  const SceneSummary s = summarize(scene);
  EXPECT_EQ(s.entities, 8u); // camera and light come from the file: no defaults added
  EXPECT_EQ(s.mesh_entities, 5u);
  EXPECT_EQ(s.unique_meshes, 5u);
  EXPECT_EQ(s.cameras, 1u);
  EXPECT_EQ(s.lights, 1u);
  EXPECT_EQ(s.reflective, 1u);
  EXPECT_EQ(s.refractive, 1u);
  EXPECT_EQ(s.animated, 1u);
  EXPECT_EQ(scene.registry.count<DefaultTag>(), 0u);

  ecs::Registry& reg = scene.registry;
  const ecs::Entity turntable = find(reg, "turntable");
  ASSERT_FALSE(turntable.is_null());
  EXPECT_FALSE(reg.has<Kinematics>(turntable)) << "a node without a mesh gets no kinematics";
  for (const ecs::Entity child : children_of(reg, turntable))
    EXPECT_EQ(reg.get<Kinematics>(child).type, Kinematics::Type::Hierarchical);
  EXPECT_EQ(children_of(reg, turntable).size(), 2u);
  EXPECT_EQ(reg.get<Kinematics>(find(reg, "ground")).type, Kinematics::Type::Static);
  EXPECT_EQ(reg.get<Material>(find(reg, "mirror ball")).reflectivity, 1.0f);
  EXPECT_EQ(reg.get<Material>(find(reg, "glass sphere")).transmission, 1.0f);
  EXPECT_EQ(reg.get<Light>(find(reg, "lamp")).type, Light::Type::Point);

  // The generator's windings agree with its normals (the geometric normal of every triangle
  // points the way its vertex normals do).
  reg.view<Mesh>().each([&](ecs::Entity e, const Mesh& mesh) {
    const TriangleMesh& m = *mesh.geometry;
    for (const uvec3& t : m.triangles) {
      const vec3 n =
          glm::cross(m.positions[t.y] - m.positions[t.x], m.positions[t.z] - m.positions[t.x]);
      if (glm::length(n) < 1e-9f) continue; // pole triangles of the sphere may be slivers
      EXPECT_GT(glm::dot(n, m.normals[t.x] + m.normals[t.y] + m.normals[t.z]), 0.0f)
          << reg.get<Name>(e).value;
    }
  });
}

// --- Bad input --------------------------------------------------------------------------------

namespace {

struct BadFile {
  const char* name;
  const char* word;   ///< a word the message must contain
  bool breaks_mesh_0; ///< load_gltf_mesh(file, 0) fails too (the problem is in the file or mesh 0)
};

const BadFile kBadFiles[] = {
    {"bad_json.gltf", "parse error", true},
    {"bad_truncated.glb", "binary", true},
    {"bad_magic.glb", "magic", true},
    {"bad_accessor_range.gltf", "out of buffer range", true},
    {"bad_index.gltf", "index 7", true},
    {"bad_nan.gltf", "non-finite", true},
    {"bad_missing_buffer.gltf", "missing.bin", true},
    {"bad_cycle.gltf", "cycle", false},
    {"bad_child_index.gltf", "out of range", false},
    {"bad_required_extension.gltf", "EXT_meshopt_compression", true},
    {"bad_draco.gltf", "KHR_draco_mesh_compression", true},
    {"bad_absurd_count.gltf", "absurd", true},
    {"bad_singular_matrix.gltf", "singular", false},
    {"bad_normal_count.gltf", "one per vertex", true},
    {"bad_morph_normal.gltf", "zero-length normal", true},
    {"bad_animation_times.gltf", "strictly increasing", false},
    {"bad_light_index.gltf", "light index 3 is out of range", false},
    {"bad_material_index.gltf", "material index 4 is out of range", false},
    {"bad_huge_translation.gltf", "outside the representable range", false},
    {"does_not_exist.gltf", "not found", true},
};

/// Runs `load` and checks it throws specula::Error naming `path` and containing `word`.
template <typename Load>
void expect_error(const fs::path& path, const std::string& word, Load&& load) {
  try {
    load();
    ADD_FAILURE() << path << " loaded without an error";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_EQ(e.file(), path.string());
    EXPECT_NE(what.find(path.filename().string()), std::string::npos) << what;
    EXPECT_NE(what.find(word), std::string::npos) << "'" << word << "' not in: " << what;
  }
}

} // namespace

TEST(GltfBadInput, EachBadFileIsAnErrorNamingFileAndProblem) {
  const LogLevel saved = log_level();
  set_log_level(LogLevel::Silent);
  for (const BadFile& bad : kBadFiles) {
    SCOPED_TRACE(bad.name);
    const fs::path path = kData / bad.name;
    expect_error(path, bad.word, [&] { (void)load_gltf_scene(path); });
  }
  set_log_level(saved);
}

TEST(GltfBadInput, MeshLoadingReportsTheSameProblems) {
  for (const BadFile& bad : kBadFiles) {
    if (!bad.breaks_mesh_0) continue;
    const std::string name = bad.name;
    SCOPED_TRACE(name);
    const fs::path path = kData / name;
    expect_error(path, bad.word, [&] { (void)load_gltf_mesh(path, 0); });
  }
}

namespace {

std::string read_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void write_bytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

} // namespace

TEST(GltfBadInput, EveryTruncationOfABinaryFileIsAnError) {
  const std::string bytes = read_bytes(kData / "box.glb");
  ASSERT_GT(bytes.size(), 100u);
  const fs::path path = fs::path(::testing::TempDir()) / "specula_truncated.glb";
  // Every length through the headers (12-byte file header, 8-byte chunk headers), then every
  // third: the chunks' contents fail alike.
  for (std::size_t length = 0; length < bytes.size(); length += length < 64 ? 1 : 3) {
    write_bytes(path, bytes.substr(0, length));
    EXPECT_THROW((void)load_gltf_scene(path), Error) << "length " << length;
  }
  fs::remove(path);
}

TEST(GltfBadInput, CorruptedFilesLoadOrFailWithAnError) {
  // Seeded corruption of valid files: each result is a scene or a specula::Error, never another
  // exception (and, under the sanitizers, never a memory error). Binary files get random bytes;
  // in JSON files digits become other digits, which keeps the JSON valid but breaks indices,
  // counts and offsets (the buffer's base64 text is left alone).
  const LogLevel saved = log_level();
  set_log_level(LogLevel::Silent);
  for (const char* source : {"box.glb", "hierarchy.gltf", "animated.gltf", "sparse.gltf"}) {
    const std::string original = read_bytes(kData / source);
    const bool json = fs::path(source).extension() == ".gltf";
    std::vector<std::size_t> positions;
    const std::size_t uri_begin = original.find("data:");
    const std::size_t uri_end = original.find('"', uri_begin);
    for (std::size_t i = 0; i < original.size(); ++i) {
      const bool in_uri = uri_begin != std::string::npos && i >= uri_begin && i < uri_end;
      if (!json || (!in_uri && std::isdigit(static_cast<unsigned char>(original[i]))))
        positions.push_back(i);
    }
    ASSERT_FALSE(positions.empty());
    std::mt19937 rng(12345);
    std::uniform_int_distribution<std::size_t> pick(0, positions.size() - 1);
    std::uniform_int_distribution<int> byte(0, 255);
    const char digits[] = "0123456789";
    const fs::path target =
        fs::path(::testing::TempDir()) / (std::string("specula_corrupted_") + source);
    for (int trial = 0; trial < 300; ++trial) {
      std::string bytes = original;
      for (int k = 0; k < 1 + trial % 3; ++k)
        bytes[positions[pick(rng)]] = json ? digits[byte(rng) % 10] : static_cast<char>(byte(rng));
      write_bytes(target, bytes);
      try {
        Scene scene = load_gltf_scene(target);
        update_world_transforms(scene.registry, 0, target.string());
      } catch (const Error& e) {
        EXPECT_EQ(e.file(), target.string()) << e.what();
      } catch (const std::exception& e) {
        ADD_FAILURE() << source << " trial " << trial << ": not a specula::Error: " << e.what();
      }
    }
    fs::remove(target);
  }
  set_log_level(saved);
}

TEST(GltfBadInput, LoadSceneRethrowsLoaderErrors) {
  const fs::path path = kData / "bad_truncated.glb";
  expect_error(path, "binary", [&] { (void)load_scene(path); });
}

// --- Real files from Debian's assimp-testmodels ------------------------------------------------

TEST(GltfAssimp, EveryFileLoadsOrFailsWithAnErrorNamingIt) {
  if (!fs::is_directory(kAssimp)) GTEST_SKIP() << kAssimp << " missing (assimp-testmodels)";
  const LogLevel saved = log_level();
  set_log_level(LogLevel::Silent);
  std::size_t loaded = 0;
  std::size_t failed = 0;
  for (const auto& entry : fs::recursive_directory_iterator(kAssimp)) {
    const std::string ext = entry.path().extension().string();
    if (ext != ".gltf" && ext != ".glb") continue;
    SCOPED_TRACE(entry.path().string());
    try {
      Scene scene = load_gltf_scene(entry.path());
      update_world_transforms(scene.registry, 0, entry.path().string()); // valid Parent links
      scene.registry.view<Mesh>().each(
          [&](const Mesh& m) { EXPECT_NO_THROW(m.geometry->validate(entry.path().string())); });
      ++loaded;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(entry.path().string()), std::string::npos) << e.what();
      ++failed;
    }
  }
  set_log_level(saved);
  EXPECT_GT(loaded, 20u);
  EXPECT_GT(failed, 5u); // the collection holds deliberately broken files
}

TEST(GltfAssimp, KnownFilesGiveKnownResults) {
  if (!fs::is_directory(kAssimp)) GTEST_SKIP() << kAssimp << " missing (assimp-testmodels)";
  const LogLevel saved = log_level();
  set_log_level(LogLevel::Silent);

  {
    Scene box = load_gltf_scene(kAssimp / "BoxTextured-glTF/BoxTextured.gltf");
    ASSERT_EQ(box.registry.count<Mesh>(), 1u);
    box.registry.view<Mesh>().each([](const Mesh& m) {
      EXPECT_EQ(m.geometry->triangle_count(), 12u);
      EXPECT_EQ(m.geometry->uvs.size(), m.geometry->vertex_count());
    });
    Scene glb = load_gltf_scene(kAssimp / "BoxTextured-glTF-Binary/BoxTextured.glb");
    EXPECT_EQ(glb.registry.count<Mesh>(), 1u);
  }
  {
    Scene cameras = load_gltf_scene(kAssimp / "cameras/Cameras.gltf");
    EXPECT_EQ(cameras.registry.count<Camera>(), 1u); // the orthographic one is skipped
    cameras.registry.view<Camera>().each([](const Camera& c) {
      expect_near(c.position, vec3(0.5f, 0.5f, 3.0f));
      EXPECT_FLOAT_EQ(c.vertical_fov, 0.7f);
    });
  }
  {
    Scene morph = load_gltf_scene(
        kAssimp / "glTF-Sample-Models/AnimatedMorphCube-glTF/AnimatedMorphCube.gltf");
    ASSERT_EQ(morph.registry.count<Animation>(), 1u);
    morph.registry.view<Animation, Mesh>().each([](const Animation& a, const Mesh& m) {
      EXPECT_EQ(a.vertices.times.size(), 127u);
      for (const auto& key : a.vertices.values) EXPECT_EQ(key.size(), m.geometry->vertex_count());
    });
  }
  {
    Scene engine = load_gltf_scene(kAssimp / "2CylinderEngine-glTF-Binary/2CylinderEngine.glb");
    std::uint64_t triangles = 0;
    engine.registry.view<Mesh>().each(
        [&](const Mesh& m) { triangles += m.geometry->triangle_count(); });
    EXPECT_GT(triangles, 100'000u);
  }
  EXPECT_NO_THROW((void)load_gltf_scene(kAssimp / "simple_skin/simple_skin.gltf"));

  expect_error(kAssimp / "draco/2CylinderEngine.gltf", "KHR_draco_mesh_compression",
               [] { (void)load_gltf_scene(kAssimp / "draco/2CylinderEngine.gltf"); });
  expect_error(kAssimp / "TestNoRootNode/NoScene.gltf", "no nodes",
               [] { (void)load_gltf_scene(kAssimp / "TestNoRootNode/NoScene.gltf"); });
  expect_error(kAssimp / "RecursiveNodes/RecursiveNodes.gltf", "cycle",
               [] { (void)load_gltf_scene(kAssimp / "RecursiveNodes/RecursiveNodes.gltf"); });
  expect_error(kAssimp / "IndexOutOfRange/IndexOutOfRange.gltf", "out of range",
               [] { (void)load_gltf_scene(kAssimp / "IndexOutOfRange/IndexOutOfRange.gltf"); });
  expect_error(kAssimp / "BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb", "non-finite", [] {
    (void)load_gltf_scene(kAssimp / "BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb");
  });
  set_log_level(saved);
}
