#pragma once
// Small helpers to build test worlds in code.

#include "specula/geometry/primitives.h"
#include "specula/render/render_job.h"
#include "specula/render/scene_layer.h"
#include "specula/render/tracer_factory.h"
#include "specula/scene/components.h"
#include "specula/scene/hierarchy.h"
#include "specula/scene/scene.h"
#include "specula/systems/schedule.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace specula::test {

inline MeshSource primitive(const std::string& name, float radius = 1.0f, vec3 size = vec3(1.0f),
                            std::uint32_t segments = 32, std::uint32_t rings = 16) {
  MeshSource s;
  s.kind = MeshSource::Kind::Primitive;
  s.primitive = name;
  s.radius = radius;
  s.size = size;
  s.segments = segments;
  s.rings = rings;
  return s;
}

inline ecs::Entity add_mesh(ecs::Registry& reg, const MeshSource& source, const Transform& t,
                            const Material& m = Material{},
                            Kinematics::Type kinematics = Kinematics::Type::Static) {
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e, t);
  reg.emplace<Mesh>(
      e, Mesh{std::make_shared<const TriangleMesh>(make_primitive(source, "test")), source, {}, 0});
  reg.emplace<Material>(e, m);
  reg.emplace<Kinematics>(e, Kinematics{kinematics});
  return e;
}

inline Transform at(const vec3& translation, const vec3& scale = vec3(1.0f),
                    const quat& rotation = quat(1, 0, 0, 0)) {
  Transform t;
  t.translation = translation;
  t.scale = scale;
  t.rotation = rotation;
  return t;
}

inline ecs::Entity add_point_light(ecs::Registry& reg, const vec3& position, float intensity) {
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e, at(position));
  Light l;
  l.intensity = intensity;
  reg.emplace<Light>(e, l);
  return e;
}

inline ecs::Entity add_camera(ecs::Registry& reg, const vec3& position, const vec3& look_at,
                              float fov_degrees = 45.0f) {
  const ecs::Entity e = reg.create();
  Camera c;
  c.position = position;
  c.look_at = look_at;
  c.vertical_fov = glm::radians(fov_degrees);
  reg.emplace<Camera>(e, c);
  return e;
}

/// An icosphere: an icosahedron subdivided `levels` times, vertices shared by every triangle
/// around them (so edges and vertices are exactly shared in float).
inline TriangleMesh icosphere(int levels) {
  const float t = (1.0f + std::sqrt(5.0f)) / 2.0f;
  TriangleMesh m;
  m.positions = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                 {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (vec3& p : m.positions) p = glm::normalize(p);
  m.triangles = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                 {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                 {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                 {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int l = 0; l < levels; ++l) {
    std::vector<uvec3> next;
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::uint32_t> mid;
    const auto midpoint = [&](std::uint32_t a, std::uint32_t b) {
      const auto key = std::minmax(a, b);
      if (const auto it = mid.find(key); it != mid.end()) return it->second;
      m.positions.push_back(glm::normalize(0.5f * (m.positions[a] + m.positions[b])));
      return mid[key] = std::uint32_t(m.positions.size() - 1);
    };
    for (const uvec3& tri : m.triangles) {
      const std::uint32_t ab = midpoint(tri.x, tri.y), bc = midpoint(tri.y, tri.z),
                          ca = midpoint(tri.z, tri.x);
      next.insert(next.end(), {uvec3(tri.x, ab, ca), uvec3(tri.y, bc, ab), uvec3(tri.z, ca, bc),
                               uvec3(ab, bc, ca)});
    }
    m.triangles = std::move(next);
  }
  m.compute_vertex_normals();
  return m;
}

/// A registry's scene as the integrators see it: the scene layer synced and a tracer of the named
/// backend built over it, with one-ray conveniences for tests.
struct TracedWorld {
  SceneLayer layer;
  std::unique_ptr<Tracer> tracer;
  std::uint64_t tick = 0;

  explicit TracedWorld(ecs::Registry& reg, std::string_view backend = "auto",
                       std::uint32_t packet_width = 1)
      : tracer(make_tracer(backend, packet_width)) {
    update(reg);
  }
  TracedWorld(ecs::Registry& reg, std::string_view backend, const TracerOptions& options)
      : tracer(make_tracer(backend, options)) {
    update(reg);
  }
  /// World transforms (as one more tick), layer and tracer brought up to date with the registry.
  void update(ecs::Registry& reg) {
    update_world_transforms(reg, ++tick);
    layer.sync(reg);
    tracer->update(layer);
  }
  [[nodiscard]] const SceneTables& tables() const { return layer.tables(); }
  [[nodiscard]] Hit intersect(const Ray& ray) const {
    Hit hit;
    tracer->intersect(std::span<const Ray>(&ray, 1), std::span<Hit>(&hit, 1));
    return hit;
  }
  [[nodiscard]] bool occluded(const Ray& ray) const {
    std::uint8_t blocked = 0;
    tracer->occluded(std::span<const Ray>(&ray, 1), std::span<std::uint8_t>(&blocked, 1));
    return blocked != 0;
  }
};

/// Options of the CPU tracer that answers hit for hit as the Vulkan device: `native-bvh` with its
/// single rays through the binary tree too, the one the device walks (the 4-wide collapse may
/// report the other of two triangles at the same t, at a shared edge). The device tests' reference.
inline TracerOptions device_mirror_options(std::uint32_t packet_width = 1) {
  TracerOptions o;
  o.packet_width = packet_width;
  o.native_wide_bvh = false;
  return o;
}

/// The names of every backend this build and machine have (tests are parameterised over them).
inline std::vector<std::string> available_backends() {
  std::vector<std::string> names;
  for (const BackendInfo& b : backends())
    if (b.available) names.emplace_back(b.name);
  return names;
}

/// A backend name as a test name part (GoogleTest allows letters, digits and underscores).
inline std::string test_name(std::string backend) {
  for (char& c : backend)
    if (c == '-') c = '_';
  return backend;
}

/// Sets up `scene` to render at width × height on the named backend, with the scene's depth and
/// background, on 2 threads; each Schedule::tick then renders a frame.
inline void prepare_scene_render(Scene& scene, TraceMode mode, const std::string& backend,
                                 std::uint32_t width, std::uint32_t height) {
  RenderJob job;
  job.backend = backend;
  job.settings.mode = mode;
  job.settings.max_depth = scene.settings.max_depth;
  job.settings.background = scene.settings.background;
  job.settings.threads = 2;
  job.image = Framebuffer(width, height);
  prepare_rendering(scene.registry, std::move(job));
}

/// One frame of `scene` (prepare_scene_render, then one tick). The registry keeps the frame's
/// resources (RenderJob, SceneLayer, ActiveTracer) for the caller to inspect.
inline Framebuffer render_scene(Scene& scene, TraceMode mode, const std::string& backend,
                                std::uint32_t width, std::uint32_t height) {
  prepare_scene_render(scene, mode, backend, width, height);
  Schedule schedule;
  schedule.tick(scene.registry, 0.0);
  return scene.registry.resource<RenderJob>().image;
}

/// One frame of a sample scene (samples/scenes/NAME.json) at size × size (render_scene).
inline Framebuffer render_sample(const std::string& scene_name, TraceMode mode,
                                 const std::string& backend, std::uint32_t size) {
  Scene scene = load_scene(std::filesystem::path(SPECULA_SOURCE_DIR) / "samples/scenes" /
                           (scene_name + ".json"));
  return render_scene(scene, mode, backend, size, size);
}

} // namespace specula::test
