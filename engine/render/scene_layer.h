#pragma once
/// \file
/// The backend-neutral scene layer: each frame the ECS becomes one flat description of what is
/// traced — the static set, the instances (entity, mesh, world-from-object), deformed meshes,
/// lights, and material and mesh tables keyed by instance — plus a delta saying what changed.
/// Every backend builds its structures from these tables and applies the delta; none reads the
/// ECS. The tables hold no pointers: 32-bit indices and offsets into flat geometry pools, laid out
/// as shaders/shared/scene_layout.h says, so the GPU path can upload them as they are.
///
/// Change comes from the transform system (TransformChanges: the entities whose world transform
/// changed), the meshes' deformation ticks (Mesh::deformed_tick) and the ECS pool versions of the
/// components the layer mirrors (ecs/registry.h rule 5): a frame in which nothing moved, deformed
/// or was added does no work proportional to the scene — no entity is visited, no vertex copied.

#include "specula/core/math.h"
#include "specula/ecs/registry.h"
#include "specula/render/emitters.h"
#include "specula/geometry/triangle_mesh.h"
#include "specula/shared/scene_layout.h"

#include <cstdint>
#include <memory>
#include <optional>
#include <unordered_map>
#include <vector>

namespace specula {

struct Mesh;

/// The render origin moves to the camera when the camera is farther than this from it (world
/// units, Euclidean). Within it, render-space coordinates near the camera stay below 4096·√3,
/// where float resolves 2^-11 ≈ 4.9e-4 or better (docs/design/large-worlds.md).
inline constexpr double kRebaseDistance = 4096.0;

/// The flat tables, in render space: world space translated by −SceneLayer::render_origin() and
/// rounded to float (GpuInstance::world_from_object and world_bounds_*, baked static positions,
/// light positions are all render-space). Instance slots are stable while their entity stays an
/// instance of the same kind; freed slots (GpuInstance::mesh == gpu::kNoIndex) are reused. Mesh
/// records likewise.
struct SceneTables {
  std::vector<gpu::GpuInstance> instances;
  std::vector<gpu::GpuMaterial> materials; ///< one per instance slot (GpuInstance::material)
  std::vector<gpu::GpuMesh> meshes;
  std::vector<gpu::GpuLight> lights;
  /// Geometry pools. The static set's meshes come first, baked in world space and contiguous:
  /// triangles [0, static_triangle_count) are every static triangle, in static_instances order.
  std::vector<vec3> positions;
  std::vector<vec3> normals;
  std::vector<uvec3> triangles;
  /// The static set: instance slots sorted by entity index (the order of their baked meshes).
  std::vector<std::uint32_t> static_instances;
  std::uint32_t static_triangle_count = 0;

  [[nodiscard]] bool live(std::uint32_t instance) const {
    return instance < instances.size() && instances[instance].mesh != gpu::kNoIndex;
  }
  [[nodiscard]] ecs::Entity entity(std::uint32_t instance) const {
    return ecs::Entity{instances[instance].entity_index, instances[instance].entity_generation};
  }
};

/// What changed in the latest sync. A consumer applies it in field order: when static_rebuilt,
/// drop the static structure and build it again from static_instances; then meshes_added;
/// instances_removed (their table entries are already freed), instances_added, instances_moved,
/// instances_deformed; last meshes_removed. Only dynamic (hierarchical and free) instances appear
/// in the instance lists: static ones are covered by static_rebuilt.
struct SceneDelta {
  bool static_rebuilt = false;
  std::vector<std::uint32_t> meshes_added;   ///< object-space meshes dynamic instances share
  std::vector<std::uint32_t> meshes_removed; ///< no instance uses them any more
  std::vector<std::uint32_t> instances_removed;
  std::vector<std::uint32_t> instances_added;
  std::vector<std::uint32_t> instances_moved;    ///< world_from_object changed
  std::vector<std::uint32_t> instances_deformed; ///< vertices rewritten in place: refit
  bool materials_changed = false;
  bool lights_changed = false;
  /// Pool offsets changed (a compaction or a static rebuild): copies of the pools are stale.
  bool geometry_relocated = false;
  /// The whole scene, not a change (SceneLayer::delta_since, for a consumer that missed syncs):
  /// drop every structure built from earlier deltas, then add what the lists name.
  bool full = false;

  [[nodiscard]] bool empty() const {
    return !static_rebuilt && meshes_added.empty() && meshes_removed.empty() &&
           instances_removed.empty() && instances_added.empty() && instances_moved.empty() &&
           instances_deformed.empty() && !materials_changed && !lights_changed &&
           !geometry_relocated && !full;
  }
};

/// The work one sync did (tests assert on it; the stats file reports it).
struct SceneLayerStats {
  std::uint32_t full_scans = 0;       ///< every mesh entity was looked at (membership changed)
  std::uint32_t entities_visited = 0; ///< entities looked at, in scans and from the moved list
  std::uint32_t static_bakes = 0;     ///< the static set was baked into world space
  std::uint32_t relayouts = 0;        ///< the geometry pools were rewritten (bake or compaction)
  std::uint64_t vertices_written = 0; ///< vertex positions written to the pools
  std::uint32_t instances_added = 0;  ///< dynamic instances (static ones count in static_bakes)
  std::uint32_t instances_removed = 0;
  std::uint32_t instances_moved = 0;
  std::uint32_t instances_deformed = 0;
  std::uint32_t static_instances = 0; ///< in the static set after the sync
  std::uint32_t static_triangles = 0;
  std::uint32_t dynamic_instances = 0;
  std::uint32_t rebases = 0; ///< the render origin moved to the camera (static set rebaked)
};

class SceneLayer {
public:
  /// Brings the tables up to date with the registry's Mesh, WorldTransform, Kinematics,
  /// Material and Light components (world transforms must be current: run after the transform
  /// system). Entities without Kinematics get the inferred kind (inferred_kinematics). Returns the
  /// delta since the previous sync; the first sync adds everything.
  const SceneDelta& sync(ecs::Registry& registry);

  [[nodiscard]] const SceneTables& tables() const { return tables_; }
  [[nodiscard]] const SceneDelta& delta() const { return delta_; }
  /// The delta a consumer (a tracer, a device scene) must apply when the last sync it applied was
  /// sync number `applied` (0: none): delta() when that was the previous sync; otherwise —
  /// a consumer made after several syncs, or one that skipped some — a delta with `full` set that
  /// adds the whole scene as it is now (the static set, every live dynamic instance, every shared
  /// mesh), so the consumer drops what it had and rebuilds. A delta without `full` is only ever
  /// valid right after the sync that made it.
  [[nodiscard]] const SceneDelta& delta_since(std::uint64_t applied) const;
  [[nodiscard]] const SceneLayerStats& stats() const { return stats_; }
  /// The area lights of the tables and the scene's features, rebuilt by every sync whose delta
  /// is not empty.
  [[nodiscard]] const EmitterTable& emitters() const { return emitters_; }
  /// The instance slot of a live entity, if it is one.
  [[nodiscard]] std::optional<std::uint32_t> instance_of(ecs::Entity entity) const;
  /// Number of syncs so far (0: never synced).
  [[nodiscard]] std::uint64_t syncs() const { return syncs_; }
  /// Whether a consumer whose last sync seen was number `seen` missed a change: some sync after
  /// it and before the latest had a delta that was not empty. (The latest sync's own delta is
  /// delta(); syncs in between that changed nothing leave delta() valid for that consumer.)
  [[nodiscard]] bool missed_changes(std::uint64_t seen) const {
    return seen + 1 < syncs_ && changed_before_ > seen;
  }
  /// Where render space's origin lies in world space. It starts at the world origin and moves to
  /// the active camera's position when a sync finds the camera farther than kRebaseDistance
  /// from it (a rebase: the static set is baked again and every dynamic instance is rewritten
  /// and reported moved). A camera that stays within kRebaseDistance of the world origin never
  /// causes one, so scenes near the origin render exactly as in world space.
  [[nodiscard]] const dvec3& render_origin() const { return render_origin_; }
  /// Rebases since the layer was made (the first sync's choice of origin is not one).
  [[nodiscard]] std::uint64_t rebases() const { return rebases_; }

private:
  struct Slot {
    ecs::Entity entity = ecs::null_entity;
    const TriangleMesh* source = nullptr; ///< Mesh::geometry as last seen
    bool deforming = false;
    std::uint64_t moved_tick = 0;              ///< WorldTransform::moved_tick as last applied
    std::uint64_t deformed_tick = 0;           ///< Mesh::deformed_tick as last applied
    std::uint32_t shared_mesh = gpu::kNoIndex; ///< the object-space mesh record it uses
    dmat4 world_from_object{1.0};              ///< dynamic instances: as last written
  };
  struct SharedMesh {
    std::shared_ptr<const TriangleMesh> source;
    std::uint32_t record = gpu::kNoIndex;
    std::uint32_t users = 0;
  };
  struct Desired {
    const std::shared_ptr<const TriangleMesh>* geometry;
    std::uint32_t kinematics;
    bool deforming;
  };

  /// Every mesh entity looked at: membership, kinds and sources checked; `moved` is the
  /// transform system's complete list since the last sync, or nullptr when there is none.
  void full_scan(ecs::Registry& registry, const std::vector<ecs::Entity>* moved);
  void apply_moved(ecs::Registry& registry, const std::vector<ecs::Entity>& moved);
  void apply_deformations(ecs::Registry& registry);
  /// A deforming instance's mesh record gets the mesh's deformed normals: written into its own
  /// range of the normals pool (appended when it had none), or first_normal = kNoIndex when there
  /// are none to match its vertices.
  void write_deformed_normals(gpu::GpuMesh& record, const Mesh& mesh);
  void refresh_materials(ecs::Registry& registry);
  void refresh_lights(ecs::Registry& registry);
  void add_instance(ecs::Registry& registry, ecs::Entity e, const Desired& d);
  void remove_instance(std::uint32_t slot);
  /// Picks the render origin for this sync (throws when the camera is out of range); true when
  /// it moved after the first sync.
  bool update_render_origin(ecs::Registry& registry);
  /// After a rebase: rewrites every dynamic instance not yet written this sync, flags the static
  /// set for rebaking and the lights for refreshing.
  void rebase_instances(ecs::Registry& registry);
  [[nodiscard]] mat4 render_from(const dmat4& world_from_object) const;
  /// Writes a dynamic instance's render-space transform and bounds; throws when its world-space
  /// extent leaves the representable range.
  void write_transform(ecs::Registry& registry, std::uint32_t slot, const dmat4& world_from_object);
  std::uint32_t acquire_shared_mesh(const std::shared_ptr<const TriangleMesh>& geometry);
  void release_shared_mesh(const TriangleMesh* source);
  std::uint32_t new_mesh_record();
  /// Rewrites the pools: the static set (baked again from the registry when rebake), then every
  /// shared mesh, then every deforming instance's vertices. Offsets change.
  void relayout(ecs::Registry& registry, bool rebake);

  SceneTables tables_;
  EmitterTable emitters_;
  SceneDelta delta_;
  SceneLayerStats stats_;
  std::vector<Slot> slots_;
  std::vector<std::uint32_t> free_slots_;
  std::vector<std::uint32_t> free_meshes_;
  std::unordered_map<std::uint32_t, std::uint32_t> slot_of_entity_; ///< by entity slot index
  std::unordered_map<const TriangleMesh*, SharedMesh> shared_;
  std::vector<std::uint32_t> deforming_; ///< slots of deforming instances
  std::uint64_t syncs_ = 0;
  std::uint64_t changed_ = 0;        ///< the latest sync whose delta was not empty (0: none)
  std::uint64_t changed_before_ = 0; ///< the same, before the latest sync
  std::uint64_t rebases_ = 0;
  mutable SceneDelta whole_;          ///< delta_since's full delta, made once per sync
  mutable std::uint64_t whole_sync_ = 0;
  dvec3 render_origin_{0.0};
  std::uint64_t transform_sequence_ = 0;
  std::uint64_t version_mesh_ = 0, version_transform_ = 0, version_kinematics_ = 0,
                version_animation_ = 0, version_parent_ = 0, version_material_ = 0;
  std::size_t live_vertices_ = 0; ///< pool vertices in use (the rest is garbage until relayout)
  /// Normals left in the pool by deforming meshes whose normals went (write_deformed_normals):
  /// garbage until relayout, which runs once they outnumber the rest (and 64 Ki), so a mesh whose
  /// normal track comes and goes again and again cannot grow the pool without bound.
  std::size_t dropped_normals_ = 0;
  bool static_moved_ = false;     ///< in the current sync: a static entity moved (warned)
};

} // namespace specula
