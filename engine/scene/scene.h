#pragma once
/// \file
/// A scene: the ECS registry holding every entity, plus the render settings from the file.
/// load_scene() reads any supported format; save_scene_json() writes Specula's JSON format.

#include "specula/core/math.h"
#include "specula/ecs/registry.h"
#include "specula/scene/components/camera.h"

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

namespace specula {

/// Defaults a scene file may set; command-line options override them.
struct RenderSettings {
  std::uint32_t width = 1024;
  std::uint32_t height = 1024;
  std::uint32_t max_depth = 5;
  vec3 background{0.0f};
  /// The animation a scene file asks to render (AFF `a START END FRAMES`, JSON
  /// settings.animation): frame i of anim_frames is at time
  /// anim_start + i·(anim_end − anim_start)/(anim_frames − 1) (a single frame at anim_start).
  /// anim_frames = 0: the file gives none; at most kMaxAnimationFrames.
  double anim_start = 0.0;
  double anim_end = 0.0;
  std::uint32_t anim_frames = 0;
  friend bool operator==(const RenderSettings&, const RenderSettings&) = default;
};

struct Scene {
  ecs::Registry registry;
  RenderSettings settings;
  /// The file the scene was read from (empty for scenes built in code).
  std::filesystem::path source;
};

/// Largest image side, triangle count and entity count any loader accepts (absurd sizes are
/// errors, not allocations).
inline constexpr std::uint32_t kMaxImageSide = 16384;
inline constexpr std::uint64_t kMaxTriangles = 100'000'000;
/// Largest vertex count of one mesh: three distinct vertices per triangle.
inline constexpr std::uint64_t kMaxVertices = 3 * kMaxTriangles;
inline constexpr std::uint64_t kMaxEntities = 10'000'000;
/// Most frames RenderSettings::anim_frames may ask for.
inline constexpr std::uint32_t kMaxAnimationFrames = 10'000'000;
/// Longest chain of secondary rays (RenderSettings::max_depth) a scene may ask for, and the
/// most the render job accepts (render/render_job.h), so `info` and `render` agree on every file.
/// The Whitted integrator traces in waves, not by recursion, and kMaxRaysPerPixel bounds what
/// deep chains cost, so 64 is honoured as it is.
inline constexpr std::uint32_t kMaxTraceDepth = 64;

/// Reads a scene by extension: .json (Specula), .gltf/.glb (glTF 2.0), .aff/.nff (BART's
/// animated NFF, aff_loader.h), .obj/.ply/.off/.stl (one mesh). Then, whatever the format: computes world transforms, which checks the hierarchy
/// (update_world_transforms), settles Kinematics (settle_kinematics: stated ones checked, the
/// others inferred), and adds the default camera and light when the file has none
/// (add_defaults). Throws specula::Error naming the file and the problem, including an entity
/// placed or extending outside the representable range (core/math.h kMaxCoordinate).
[[nodiscard]] Scene load_scene(const std::filesystem::path& path);

/// Marks the entity added by add_defaults, so the writer leaves it out of the saved file.
struct DefaultTag {};

/// When the scene has no Camera, adds one framing the world bounds: looking at the bounds' centre
/// from the +Z side, raised 20° above it, at the distance where the bounding sphere fills the
/// vertical field of view (45°), aspect from settings. When it has no Light and no emissive
/// mesh (an area light), adds a point light
/// at the camera position with intensity distance² (so a surface at the bounds' centre facing it
/// gets irradiance 1, at any scale). Both carry DefaultTag.
void add_defaults(Scene& scene);

/// The camera to render from: the Camera of the live entity with the lowest slot index (so the
/// choice does not depend on iteration order). Empty when the scene has none.
[[nodiscard]] std::optional<Camera> active_camera(ecs::Registry& registry);

/// World-space bounds of every mesh entity, in double (world transforms must be current).
[[nodiscard]] DAabb world_bounds(ecs::Registry& registry);

/// What `specula info` prints.
struct SceneSummary {
  std::size_t entities = 0;
  std::size_t mesh_entities = 0;
  std::size_t unique_meshes = 0;
  std::uint64_t triangles = 0; ///< placed (instanced meshes count once per entity)
  std::size_t materials = 0;   ///< distinct Material values
  std::size_t lights = 0;          ///< punctual (Light components)
  std::size_t emissive_meshes = 0; ///< mesh entities whose material emits (area lights)
  std::size_t cameras = 0;
  std::size_t reflective = 0; ///< entities with reflectivity > 0
  std::size_t refractive = 0; ///< entities with transmission > 0
  std::size_t ray_cache_cubes = 0;
  std::size_t animated = 0;
  DAabb bounds;
};
[[nodiscard]] SceneSummary summarize(Scene& scene);

} // namespace specula
