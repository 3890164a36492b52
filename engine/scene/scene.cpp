#include "specula/scene/scene.h"

#include "specula/core/error.h"
#include "specula/scene/aff_loader.h"
#include "specula/scene/components.h"
#include "specula/scene/gltf_loader.h"
#include "specula/scene/hierarchy.h"
#include "specula/scene/json_scene.h"
#include "specula/scene/kinematics_rules.h"
#include "specula/scene/mesh_io.h"

#include <algorithm>
#include <cctype>
#include <set>
#include <system_error>
#include <unordered_map>

namespace specula {
namespace {

std::string lower_extension(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

Scene scene_from_mesh_file(const std::filesystem::path& path) {
  Scene scene;
  scene.source = path;
  auto mesh = std::make_shared<const TriangleMesh>(load_mesh_file(path));
  ecs::Registry& reg = scene.registry;
  const ecs::Entity e = reg.create();
  reg.emplace<Name>(e, path.stem().string());
  reg.emplace<Transform>(e);
  MeshSource source;
  source.kind = MeshSource::Kind::File;
  source.path = path.filename().string();
  reg.emplace<Mesh>(e, Mesh{std::move(mesh), source, {}, 0});
  reg.emplace<Material>(e);
  return scene;
}

/// Every mesh entity's world-space extent within the representable range, so that `info` refuses
/// what `render` could not trace (a scale times vertex coordinates; placement is checked by
/// update_world_transforms).
void check_world_extents(ecs::Registry& reg, const std::string& context) {
  std::unordered_map<const TriangleMesh*, Aabb> object_bounds;
  reg.view<Mesh, WorldTransform>().each([&](ecs::Entity e, const Mesh& mesh,
                                            const WorldTransform& wt) {
    if (!mesh.geometry) return;
    auto [it, added] = object_bounds.try_emplace(mesh.geometry.get());
    if (added) it->second = mesh.geometry->bounds();
    const DAabb world = DAabb::transformed(it->second, wt.world_from_object);
    if (!in_range(world.min) || !in_range(world.max))
      throw Error(context, entity_label(reg, e) + " extends from " + format_position(world.min) +
                               " to " + format_position(world.max) + ", outside " +
                               kCoordinateRangeText);
  });
}

} // namespace

Scene load_scene(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw Error(path.string(), "file not found");
  if (std::filesystem::is_directory(path, ec))
    throw Error(path.string(), "is a directory, not a scene file");
  const std::string ext = lower_extension(path);
  Scene scene;
  if (ext == ".json") {
    scene = load_json_scene(path);
  } else if (ext == ".gltf" || ext == ".glb") {
    scene = load_gltf_scene(path);
  } else if (ext == ".aff" || ext == ".nff") {
    scene = load_aff_scene(path);
  } else if (is_mesh_file_extension(ext)) {
    scene = scene_from_mesh_file(path);
  } else {
    throw Error(path.string(), "unknown file extension '" + ext +
                                   "' (expected .json, .gltf, .glb, .aff, .nff, .obj, .ply, .off or .stl)");
  }
  scene.source = path;
  if (scene.registry.alive() > kMaxEntities)
    throw Error(path.string(), "scene has more than " + std::to_string(kMaxEntities) + " entities");
  update_world_transforms(scene.registry, 0, path.string());
  check_world_extents(scene.registry, path.string());
  settle_kinematics(scene.registry, path.string());
  add_defaults(scene);
  return scene;
}

std::optional<Camera> active_camera(ecs::Registry& registry) {
  std::optional<Camera> best;
  std::uint32_t best_index = 0;
  registry.view<Camera>().each([&](ecs::Entity e, const Camera& c) {
    if (!best || e.index < best_index) {
      best = c;
      best_index = e.index;
    }
  });
  return best;
}

DAabb world_bounds(ecs::Registry& registry) {
  DAabb bounds;
  registry.view<Mesh, WorldTransform>().each([&](const Mesh& mesh, const WorldTransform& wt) {
    if (!mesh.geometry) return;
    Aabb local;
    for (const vec3& p : mesh.positions()) local.grow(p);
    bounds.grow(DAabb::transformed(local, wt.world_from_object));
  });
  return bounds;
}

void add_defaults(Scene& scene) {
  ecs::Registry& reg = scene.registry;
  const bool has_camera = reg.count<Camera>() > 0;
  // Emissive surfaces are area lights: a scene lit by them alone needs no default light.
  bool has_light = reg.count<Light>() > 0;
  reg.view<Mesh, Material>().each([&](const Mesh&, const Material& m) {
    has_light = has_light || m.emission != vec3(0.0f);
  });
  if (has_camera && has_light) return;

  DAabb bounds = world_bounds(reg);
  if (bounds.empty()) bounds = DAabb{dvec3(-1.0), dvec3(1.0)};
  const dvec3 center = bounds.center();
  const float radius = std::max(0.5f * float(glm::length(bounds.extent())), 1e-6f);
  const float aspect = float(scene.settings.width) / float(std::max(1u, scene.settings.height));

  Camera camera;
  camera.vertical_fov = glm::radians(45.0f);
  camera.aspect = aspect;
  camera.look_at = center;
  const float fov = std::min(camera.vertical_fov, camera.vertical_fov * aspect);
  const float distance = radius / std::sin(0.5f * fov);
  const float elevation = glm::radians(20.0f);
  camera.position = center + dvec3(distance * vec3(0.0f, std::sin(elevation), std::cos(elevation)));

  if (!has_camera) {
    const ecs::Entity e = reg.create();
    reg.emplace<Name>(e, "default camera");
    reg.emplace<Camera>(e, camera);
    reg.emplace<DefaultTag>(e);
  } else {
    // Place the default light relative to the scene's own camera.
    reg.view<Camera>().each([&](const Camera& c) { camera = c; });
  }
  if (!has_light) {
    const ecs::Entity e = reg.create();
    reg.emplace<Name>(e, "default light");
    Transform t;
    t.translation = camera.position;
    reg.emplace<Transform>(e, t);
    WorldTransform wt;
    wt.world_from_object = t.parent_from_local();
    reg.emplace<WorldTransform>(e, wt);
    Light light;
    light.type = Light::Type::Point;
    // Irradiance I/d² at the bounds' centre is 1 whatever the scene's scale.
    const float d = float(glm::length(camera.position - center));
    light.intensity = std::max(d * d, 1e-12f);
    reg.emplace<Light>(e, light);
    reg.emplace<DefaultTag>(e);
  }
}

SceneSummary summarize(Scene& scene) {
  ecs::Registry& reg = scene.registry;
  SceneSummary s;
  s.entities = reg.alive();
  std::set<const TriangleMesh*> unique;
  std::vector<Material> materials;
  reg.view<Mesh>().each([&](ecs::Entity e, const Mesh& mesh) {
    ++s.mesh_entities;
    if (mesh.geometry) {
      unique.insert(mesh.geometry.get());
      s.triangles += mesh.geometry->triangle_count();
    }
    if (const Material* m = reg.try_get<Material>(e)) {
      if (std::find(materials.begin(), materials.end(), *m) == materials.end())
        materials.push_back(*m);
      s.reflective += m->is_reflective() ? 1 : 0;
      s.refractive += m->is_refractive() ? 1 : 0;
      s.emissive_meshes += glm::any(glm::greaterThan(m->emission, vec3(0.0f))) ? 1 : 0;
    }
  });
  s.unique_meshes = unique.size();
  s.materials = materials.size();
  s.lights = reg.count<Light>();
  s.cameras = reg.count<Camera>();
  s.ray_cache_cubes = reg.count<RayCacheCube>();
  s.animated = reg.count<Animation>() + reg.count<CameraPath>();
  s.bounds = world_bounds(reg);
  return s;
}

} // namespace specula
