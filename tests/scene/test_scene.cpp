// load_scene dispatch, default camera/light, summaries.

#include "specula/core/error.h"
#include "specula/scene/components.h"
#include "specula/scene/hierarchy.h"
#include "specula/scene/scene.h"

#include <glm/gtc/matrix_transform.hpp>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

namespace specula {
namespace {

namespace fs = std::filesystem;

std::string error_of(const fs::path& path) {
  try {
    (void)load_scene(path);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

/// A mesh entity with a unit box's 8 corners (two triangles suffice for bounds).
ecs::Entity add_box(Scene& scene, const vec3& center, const vec3& half) {
  auto mesh = std::make_shared<TriangleMesh>();
  for (int i = 0; i < 8; ++i)
    mesh->positions.push_back(vec3(i & 1 ? 1 : -1, i & 2 ? 1 : -1, i & 4 ? 1 : -1));
  mesh->triangles = {uvec3(0, 1, 2), uvec3(5, 6, 7)};
  const ecs::Entity e = scene.registry.create();
  Transform t;
  t.translation = center;
  t.scale = half;
  scene.registry.emplace<Transform>(e, t);
  scene.registry.emplace<Mesh>(e, Mesh{mesh, {}, {}, 0});
  scene.registry.emplace<Material>(e);
  return e;
}

/// Whether p is inside the camera's view frustum (pinhole, vertical fov, aspect).
bool in_frustum(const Camera& c, const vec3& p) {
  const mat4 view = glm::lookAt(vec3(c.position), vec3(c.look_at), c.up);
  const vec3 q = vec3(view * vec4(p, 1.0f));
  if (q.z >= 0.0f) return false;
  const float tan_half = std::tan(0.5f * c.vertical_fov);
  return std::abs(q.y) <= -q.z * tan_half * 1.0001f && std::abs(q.x) <= -q.z * tan_half * c.aspect * 1.0001f;
}

TEST(Scene, MissingFileNamesTheFile) {
  const std::string msg = error_of("/nonexistent/dir/scene.json");
  EXPECT_NE(msg.find("/nonexistent/dir/scene.json"), std::string::npos) << msg;
  EXPECT_NE(msg.find("not found"), std::string::npos) << msg;
}

TEST(Scene, UnknownExtensionIsRejectedByName) {
  const fs::path path = fs::temp_directory_path() / "specula_test_scene.xyz";
  std::ofstream(path) << "hello";
  const std::string msg = error_of(path);
  fs::remove(path);
  EXPECT_NE(msg.find("specula_test_scene.xyz"), std::string::npos) << msg;
  EXPECT_NE(msg.find("'.xyz'"), std::string::npos) << msg;
}

TEST(Scene, DirectoryIsNotAScene) {
  const std::string msg = error_of(fs::temp_directory_path());
  EXPECT_NE(msg.find("directory"), std::string::npos) << msg;
}

TEST(Scene, DefaultCameraFramesEveryCornerOfTheBounds) {
  for (const vec3 half : {vec3(1.0f), vec3(10.0f, 0.1f, 0.1f), vec3(0.1f, 5.0f, 0.1f), vec3(1e4f), vec3(1e-3f)}) {
    Scene scene;
    scene.settings.width = 640;
    scene.settings.height = 360;
    add_box(scene, vec3(3, -2, 7), half);
    update_world_transforms(scene.registry, 0);
    add_defaults(scene);
    ASSERT_EQ(scene.registry.count<Camera>(), 1u);
    Camera camera;
    scene.registry.view<Camera>().each([&](const Camera& c) { camera = c; });
    EXPECT_NEAR(camera.aspect, 640.0f / 360.0f, 1e-6f);
    const DAabb b = world_bounds(scene.registry);
    for (int i = 0; i < 8; ++i) {
      const vec3 corner(i & 1 ? b.max.x : b.min.x, i & 2 ? b.max.y : b.min.y, i & 4 ? b.max.z : b.min.z);
      EXPECT_TRUE(in_frustum(camera, corner)) << "half extent " << half.x << "," << half.y << "," << half.z
                                             << " corner " << i;
    }
  }
}

TEST(Scene, DefaultLightIsAddedOnlyWhenThereIsNone) {
  Scene scene;
  add_box(scene, vec3(0), vec3(1));
  update_world_transforms(scene.registry, 0);
  add_defaults(scene);
  EXPECT_EQ(scene.registry.count<Light>(), 1u);
  EXPECT_EQ(scene.registry.count<DefaultTag>(), 2u);
  add_defaults(scene); // idempotent
  EXPECT_EQ(scene.registry.count<Light>(), 1u);
  EXPECT_EQ(scene.registry.count<Camera>(), 1u);

  Scene lit;
  add_box(lit, vec3(0), vec3(1));
  const ecs::Entity light = lit.registry.create();
  lit.registry.emplace<Transform>(light);
  lit.registry.emplace<Light>(light);
  update_world_transforms(lit.registry, 0);
  add_defaults(lit);
  EXPECT_EQ(lit.registry.count<Light>(), 1u);
  EXPECT_EQ(lit.registry.count<Camera>(), 1u);
  EXPECT_EQ(lit.registry.count<DefaultTag>(), 1u);
}

TEST(Scene, EmissiveMeshesCountAsLights) {
  // A scene lit by an area light alone gets a default camera but no default point light.
  Scene scene;
  add_box(scene, vec3(0), vec3(1));
  const ecs::Entity panel = add_box(scene, vec3(0, 3, 0), vec3(1, 0.1f, 1));
  scene.registry.get<Material>(panel).emission = vec3(2.0f);
  update_world_transforms(scene.registry, 0);
  add_defaults(scene);
  EXPECT_EQ(scene.registry.count<Light>(), 0u);
  EXPECT_EQ(scene.registry.count<Camera>(), 1u);
  EXPECT_EQ(scene.registry.count<DefaultTag>(), 1u);
}

TEST(Scene, DefaultLightGivesUnitIrradianceAtTheCentre) {
  Scene scene;
  add_box(scene, vec3(0), vec3(2));
  update_world_transforms(scene.registry, 0);
  add_defaults(scene);
  vec3 light_pos{0.0f};
  float intensity = 0.0f;
  scene.registry.view<Light, WorldTransform>().each([&](const Light& l, const WorldTransform& wt) {
    light_pos = vec3(wt.world_from_object[3]);
    intensity = l.intensity;
  });
  const float d = glm::length(light_pos - vec3(world_bounds(scene.registry).center()));
  const float radius = 0.5f * float(glm::length(world_bounds(scene.registry).extent()));
  EXPECT_NEAR(intensity / (d * d), 1.0f, 1e-4f); // E = I / d²
  EXPECT_GT(d, radius);                          // the light is outside the scene
}

TEST(Scene, SummaryCountsPlacedTrianglesAndDistinctMaterials) {
  Scene scene;
  const ecs::Entity a = add_box(scene, vec3(0), vec3(1));
  const ecs::Entity b = add_box(scene, vec3(5, 0, 0), vec3(1));
  scene.registry.get<Mesh>(b).geometry = scene.registry.get<Mesh>(a).geometry; // instanced
  Material mirror;
  mirror.reflectivity = 1.0f;
  scene.registry.get<Material>(b) = mirror;
  update_world_transforms(scene.registry, 0);
  const SceneSummary s = summarize(scene);
  EXPECT_EQ(s.mesh_entities, 2u);
  EXPECT_EQ(s.unique_meshes, 1u);
  EXPECT_EQ(s.triangles, 4u);
  EXPECT_EQ(s.materials, 2u);
  EXPECT_EQ(s.reflective, 1u);
  EXPECT_FLOAT_EQ(s.bounds.max.x, 6.0f);
  EXPECT_FLOAT_EQ(s.bounds.min.x, -1.0f);
}

TEST(Scene, RotationLookingAlongTurnsMinusZTowardsTheDirection) {
  for (const vec3 dir : {vec3(1, 0, 0), vec3(0, 0, -1), vec3(0, 0, 1), vec3(0, -1, 0), vec3(1, 2, 3)}) {
    const quat q = rotation_looking_along(dir);
    const vec3 forward = q * vec3(0, 0, -1);
    EXPECT_NEAR(glm::dot(forward, glm::normalize(dir)), 1.0f, 1e-5f);
    EXPECT_NEAR(glm::length(q), 1.0f, 1e-5f);
  }
}

// --- The representable range (core/math.h kMaxCoordinate, docs/design/large-worlds.md) ----------
// Positions, mesh coordinates and primitive sizes beyond ±1e12 used to pass `info` and abort
// inside Embree at render time (issue 13, cause 1). Each is now an error naming the file and the
// field (or the entity, for what composition produces), so `info` refuses them too.

struct RangeCase {
  const char* file;     ///< name in the temporary directory
  std::string text;     ///< its contents
  const char* field;    ///< Error::field() ("" when the entity is named instead)
  const char* fragment; ///< a piece of the message
};

std::string entities(const std::string& list) {
  return R"({"format": "specula-scene", "version": 1, "entities": [)" + list + "]}";
}

const char* const kCamera =
    R"({"name": "camera", "camera": {"position": [0, 0, 5], "look_at": [0, 0, 0]}})";

std::vector<RangeCase> range_cases() {
  return {
      {"range_box_size.json", entities(R"({"name": "slab", "mesh": {"primitive": "box", "size": 1.8e19}})"),
       "entities[0].mesh.size", "length 1.8e+19 is outside the representable range"},
      {"range_sphere_radius.json",
       entities(R"({"name": "ball", "mesh": {"primitive": "sphere", "radius": 1e13}})"),
       "entities[0].mesh.radius", "outside the representable range"},
      {"range_translation.json",
       entities(R"({"name": "far", "transform": {"translation": [0, 1e19, 0]}, "mesh": {"primitive": "sphere"}})"),
       "entities[0].transform.translation[1]", "coordinate 1e+19 is outside the representable range"},
      {"range_camera_1e19.json",
       entities(R"({"name": "camera", "camera": {"position": [0, 0, 1e19], "look_at": [0, 0, 0]}})"),
       "entities[0].camera.position[2]", "outside the representable range"},
      // Used to say "up vector is parallel to the view direction" (the float difference overflowed).
      {"range_camera_1e30.json",
       entities(R"({"name": "camera", "camera": {"position": [1e30, 0, 0], "look_at": [0, 0, 0]}})"),
       "entities[0].camera.position[0]", "outside the representable range"},
      {"range_look_at.json",
       entities(R"({"name": "camera", "camera": {"position": [0, 0, 0], "look_at": [0, 0, -1e19]}})"),
       "entities[0].camera.look_at[2]", "outside the representable range"},
      {"range_animation_key.json",
       entities(R"({"name": "mover", "animation": {"translation": {"times": [0, 1], "values": [[0, 0, 0], [1e19, 0, 0]]}}})"),
       "entities[0].animation.translation.values[1][0]", "outside the representable range"},
      {"range_camera_path_key.json",
       entities(R"({"name": "camera", "camera": {"position": [0, 0, 5], "look_at": [0, 0, 0]},
                   "camera_path": {"keys": [{"time": 0, "position": [0, 0, 5], "look_at": [0, 0, 0]},
                                            {"time": 1, "position": [0, 0, 2e12], "look_at": [0, 0, 0]}]}})"),
       "entities[0].camera_path.keys[1].position[2]", "outside the representable range"},
      {"range_inline_vertex.json",
       entities(R"({"name": "tri", "mesh": {"inline": {"positions": [[0, 0, 0], [1e30, 0, 0], [0, 1, 0]], "triangles": [[0, 1, 2]]}}})"),
       "", "vertex 1 has a coordinate outside the representable range"},
      // Composition: each value is in range, the product is not.
      {"range_parent_scale.json",
       entities(std::string(kCamera) + R"(, {"name": "giant", "transform": {"scale": 1e10}},
                {"name": "far child", "parent": "giant", "transform": {"translation": [0, 0, 1e5]}, "mesh": {"primitive": "sphere"}})"),
       "", "\"far child\" is placed at (0, 0, 1e+15), outside the representable range"},
      {"range_scaled_extent.json",
       entities(std::string(kCamera) + R"(, {"name": "balloon", "transform": {"scale": 1e8}, "mesh": {"primitive": "sphere", "radius": 1e5}})"),
       "", "\"balloon\" extends from"},
      {"range_vertex.stl",
       "solid far\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1e30 0 0\n"
       "   vertex 0 1 0\n  endloop\n endfacet\nendsolid far\n",
       "", "has a coordinate outside the representable range"},
      {"range_vertex.obj", "v 0 0 0\nv 0 2e12 0\nv 1 0 0\nf 1 2 3\n", "",
       "has a coordinate outside the representable range"},
      {"range_node.gltf",
       R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
           "nodes": [{"name": "far", "translation": [1e19, 0, 0]}]})",
       "nodes[0].translation", "outside the representable range"},
      {"range_node_matrix.gltf",
       R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
           "nodes": [{"name": "far", "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,-3e12,1]}]})",
       "nodes[0].matrix", "outside the representable range"},
  };
}

TEST(Scene, CoordinatesOutsideTheRangeAreErrorsNamingTheFileAndField) {
  for (const RangeCase& c : range_cases()) {
    const fs::path path = fs::temp_directory_path() / c.file;
    std::ofstream(path, std::ios::binary) << c.text;
    try {
      (void)load_scene(path);
      ADD_FAILURE() << c.file << " loaded without an error";
    } catch (const Error& e) {
      const std::string what = e.what();
      EXPECT_EQ(e.file(), path.string()) << what;
      if (*c.field != '\0') {
        EXPECT_EQ(e.field(), c.field) << what;
      }
      EXPECT_NE(what.find(c.fragment), std::string::npos)
          << c.file << ": expected \"" << c.fragment << "\" in: " << what;
      EXPECT_EQ(what.find("parallel"), std::string::npos) << what;
    }
    fs::remove(path);
  }
}

TEST(Scene, CoordinatesJustInsideTheRangeLoad) {
  const fs::path path = fs::temp_directory_path() / "range_just_inside.json";
  std::ofstream(path, std::ios::binary) << entities(
      R"({"name": "camera", "camera": {"position": [-1e12, 1e12, 0.999e12], "look_at": [-1e12, 1e12, 0]}},
         {"name": "big", "mesh": {"primitive": "box", "size": 1e12}},
         {"name": "lamp", "transform": {"translation": [1e12, -1e12, 1e12]}, "light": {"type": "point"}},
         {"name": "giant", "transform": {"scale": 1e7}},
         {"name": "child", "parent": "giant", "transform": {"translation": [0, 0, 1e5]}, "light": {"type": "point"}})");
  Scene scene = load_scene(path);
  fs::remove(path);
  const Camera camera = *active_camera(scene.registry);
  EXPECT_EQ(camera.position, dvec3(-1e12, 1e12, 0.999e12)) << "positions are kept in double";
  scene.registry.view<Name, WorldTransform>().each([](const Name& n, const WorldTransform& wt) {
    if (n.value == "child") {
      EXPECT_EQ(wt.world_from_object[3].z, 1e12) << "1e7 × 1e5, composed in double";
    }
  });
}

} // namespace
} // namespace specula
