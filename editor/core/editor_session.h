#pragma once
/// \file
/// The editor's session and its action layer: one loaded scene, its schedule and render job, and
/// every edit the editor can make. Mouse, keyboard, the ImGui panels and `--script` all call these
/// actions; none writes components any other way. Every edit is a command holding the edited
/// entities' components before and after (EntitySnapshot), so undo restores them bit for bit, and
/// it writes them with emplace_or_replace / remove, so the next tick's transform and scene-layer
/// systems see the change as they see an animation's (registry rule 5).

#include "editor/core/cache_view.h"
#include "specula/cache/cache_settings.h"
#include "specula/core/math.h"
#include "specula/render/render_job.h"
#include "specula/scene/components.h"
#include "specula/scene/mesh_library.h"
#include "specula/scene/scene.h"
#include "specula/systems/schedule.h"

#include <cstdint>
#include <deque>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

namespace specula::editor {

using dvec2 = glm::dvec2;

/// A stable name for an entity across delete/undo (which makes a new ECS handle).
using EditorId = std::uint64_t;
inline constexpr EditorId kNoId = 0;

/// Every component the editor edits or recreates, by value; Parent as an EditorId.
struct EntitySnapshot {
  std::optional<Name> name;
  std::optional<Transform> transform;
  std::optional<EditorId> parent;
  std::optional<Mesh> mesh;
  std::optional<Material> material;
  std::optional<Kinematics> kinematics;
  std::optional<Light> light;
  std::optional<Camera> camera;
  std::optional<CameraPath> camera_path;
  std::optional<RayCacheCube> ray_cache_cube;
  std::optional<Animation> animation;
  bool default_tag = false; ///< DefaultTag: the writer leaves the entity out
};

/// How the viewport renders (switchable on a live session).
struct ViewSettings {
  std::string backend = "auto";
  TraceMode mode = TraceMode::Whitted;
  /// Longest secondary chain; empty: the scene file's (RenderSettings::max_depth).
  std::optional<std::uint32_t> max_depth;
  std::uint32_t width = 960, height = 540;
  std::uint32_t threads = 0;
  cache::CacheSettings cache;
};

enum class GizmoMode { Translate, Rotate, Scale };

/// Radians a rotate drag turns per pixel of its screen vector's x.
inline constexpr double kRotateRadiansPerPixel = 0.01;

/// Per-frame history the overlay plots.
struct FrameSample {
  double ms = 0.0;
  std::vector<double> system_ms; ///< Schedule::system_names() order
  double rays_per_second = 0.0;
};

class EditorSession {
public:
  /// Loads the scene (load_scene) and prepares rendering with `view`. Throws specula::Error.
  EditorSession(const std::filesystem::path& scene_path, ViewSettings view);

  // --- frames -----------------------------------------------------------------------------------
  /// Runs the schedule once (dt seconds) and records the history.
  void tick(double dt = 1.0 / 60.0);
  /// Renders from the next tick on at view width·scale × height·scale (dynamic resolution:
  /// the window shows the frame scaled up; picking and gizmos work in the frame's own pixels).
  /// 1 is the view's size.
  void set_render_scale(float scale);
  /// The latest frame as shown: the render job's image, or with the cache view on, that image
  /// with the cached objects tinted (cache_view.h). A frame kept on a shared device
  /// (share_device) is read back first.
  [[nodiscard]] const Framebuffer& frame() const;
  /// Its size (no readback).
  [[nodiscard]] std::pair<std::uint32_t, std::uint32_t> frame_size() const;
  /// Renders on `device` (a window's: present::Window::context) where the backend is a Vulkan
  /// one, keeping cast and Whitted frames there so that the window draws device_frame() in
  /// place; frame() reads one back only when the pixels are asked for (a screenshot). The cache
  /// view's tint is drawn on the host: with it on, frames are read back as before. Null: stop
  /// sharing. The tracer is made again when the backend is a Vulkan one.
  void share_device(std::shared_ptr<gpu::Context> device);
  /// The latest frame where it is on the shared device, or null (a CPU backend, path and shadow
  /// modes, the cache view, no device shared, or already read back).
  [[nodiscard]] const gpu::DeviceFrame* device_frame() const;
  [[nodiscard]] const std::deque<FrameSample>& history() const { return history_; }
  /// The cache view (cache_view.h): from the next tick on, frame() tints each cached object's
  /// pixels by the texels their reflections read; off, it shows the rendered frame again at once.
  void set_cache_view(bool on);
  [[nodiscard]] bool cache_view() const { return cache_view_; }
  /// What the latest tick's cache view counted (zeros with the view off or without caches).
  [[nodiscard]] const CacheViewCounts& cache_view_counts() const { return cache_view_counts_; }
  static constexpr std::size_t kHistory = 120;

  // --- render settings (live) -------------------------------------------------------------------
  [[nodiscard]] const ViewSettings& view() const { return view_; }
  /// A new tracer for the live layer: its first update catches up through delta_since.
  void set_backend(const std::string& backend);
  void set_mode(TraceMode mode);
  void set_max_depth(std::uint32_t depth);
  /// Caches on or off (or another policy): the render job is prepared again (new layer, store).
  void set_cache(const cache::CacheSettings& cache);

  // --- selection --------------------------------------------------------------------------------
  /// Casts the camera ray through pixel (x, y) of the last frame with the active tracer and
  /// selects the entity hit (none on a miss). Returns the selection.
  std::optional<ecs::Entity> click(std::uint32_t x, std::uint32_t y);
  void select(ecs::Entity e);
  /// Selects the first entity (lowest index) with this Name; throws when there is none.
  void select_by_name(std::string_view name);
  void clear_selection() { selected_ = kNoId; }
  [[nodiscard]] std::optional<ecs::Entity> selected() const;

  // --- edits (all undoable) ---------------------------------------------------------------------
  /// Pixels per world unit along world axis `axis` (0 x, 1 y, 2 z) at the entity's origin: the
  /// screen vector of one unit, from the camera and the frame size.
  [[nodiscard]] dvec2 screen_axis(ecs::Entity e, int axis) const;
  /// Drags the selection's gizmo handle for `axis` by a screen vector (pixels): translate and
  /// scale move by the drag's projection on screen_axis in world units; rotate turns by
  /// kRotateRadiansPerPixel per pixel of drag.x about the world axis.
  void drag(GizmoMode mode, int axis, dvec2 screen_delta);
  /// Sets a field by path ("Transform.translation.x", "Material.reflectivity",
  /// "Kinematics.type", "RayCacheCube.enabled", ...; fields.h lists them) from text.
  void set_field(ecs::Entity e, std::string_view path, std::string_view value);
  /// Adds a primitive ("sphere", "box", "plane", "cylinder", "cone") or a mesh file at the
  /// origin, selects it and returns it.
  ecs::Entity add_primitive(const std::string& primitive, const std::string& name);
  ecs::Entity add_mesh_file(const std::filesystem::path& file, const std::string& name);
  /// Deletes the entity and its Parent subtree; refuses to delete the scene's last camera.
  void remove(ecs::Entity e);
  /// Sets e's parent (null_entity: none); the local Transform stays as it is, now relative to
  /// the new parent. Throws when the parent is e or one of its descendants, or has no Transform.
  void reparent(ecs::Entity e, ecs::Entity parent);
  bool undo();
  bool redo();
  /// Between begin_gesture and end_gesture (a mouse drag: button down to up), successive edits
  /// of one entity make one undo step: Ctrl+Z after a drag undoes the whole drag, not its last
  /// mouse move. An undo, a redo or an edit of another entity starts a new step.
  /// A gesture that drags a static entity (or one with static descendants) makes those entities
  /// hierarchical until it ends, so the drag moves instances instead of rebuilding the static
  /// structure every frame: two rebuilds per drag (out of the static set, back in) instead of one
  /// per mouse move. Snapshots, undo steps and saved files keep their own kinematics; an undo, a
  /// redo, a field edit, a delete or a save ends the switch early.
  void begin_gesture();
  void end_gesture();
  [[nodiscard]] std::size_t undo_depth() const { return undo_.size(); }

  // --- camera (not undoable: navigation) --------------------------------------------------------
  [[nodiscard]] Camera camera();
  void set_camera(const Camera& camera);
  /// Points the camera at the selection's bounds, from the current direction.
  void frame_selected();

  // --- files ------------------------------------------------------------------------------------
  void save(const std::filesystem::path& path);
  /// The last frame as PNG.
  void screenshot(const std::filesystem::path& path) const;

  // --- access -----------------------------------------------------------------------------------
  [[nodiscard]] ecs::Registry& registry() { return scene_.registry; }
  [[nodiscard]] Scene& scene() { return scene_; }
  [[nodiscard]] EntitySnapshot snapshot(ecs::Entity e) const;
  [[nodiscard]] ecs::Entity entity(EditorId id) const;
  [[nodiscard]] EditorId id_of(ecs::Entity e) const;
  /// Renders the current layer state once without caches (reference for the cached frame).
  [[nodiscard]] Framebuffer render_uncached();

private:
  struct Change {
    EditorId id;
    std::optional<EntitySnapshot> before, after; ///< empty: the entity does not exist
  };
  using Command = std::vector<Change>;
  void execute(Command command);
  float render_scale_ = 1.0f;
  bool gesture_ = false;        ///< inside begin_gesture / end_gesture
  bool gesture_merges_ = false; ///< undo_.back() is this gesture's step, edits merge into it
  EditorId drag_checked_ = kNoId; ///< the entity this gesture last ran unfreeze_for_drag on
  /// Entities this gesture's drags made hierarchical, with their own Kinematics (none: the
  /// component was absent, which means static).
  std::vector<std::pair<EditorId, std::optional<Kinematics>>> drag_kinematics_;
  /// Makes e's static subtree hierarchical for the rest of the gesture (begin_gesture).
  void unfreeze_for_drag(ecs::Entity e);
  /// Gives the entities unfreeze_for_drag switched their own Kinematics back.
  void restore_drag_kinematics();
  void apply(const Command& command, bool forward);
  /// One undoable edit of e: `change` edits a copy of its snapshot (and may throw: no change).
  void edit(ecs::Entity e, const std::function<void(EntitySnapshot&)>& change);
  /// Writes `state` into the entity; with `other`, only the components that differ from it.
  void write(EditorId id, const EntitySnapshot& state, const EntitySnapshot* other);
  ecs::Entity add_entity(EntitySnapshot s);
  /// A new free entity with this mesh, a default Transform and Material; selected.
  ecs::Entity add_mesh_entity(const MeshSource& source, const std::string& name);
  EditorId assign_id(ecs::Entity e);
  void prepare();
  [[nodiscard]] std::vector<ecs::Entity> subtree(ecs::Entity root);

  Scene scene_;
  ViewSettings view_;
  Schedule schedule_;
  MeshLibrary meshes_;
  EditorId next_id_ = 1;
  std::unordered_map<EditorId, ecs::Entity> entities_;
  std::unordered_map<std::uint32_t, EditorId> ids_; ///< by entity index
  EditorId selected_ = kNoId;
  std::vector<Command> undo_, redo_;
  std::deque<FrameSample> history_;
  bool cache_view_ = false;
  bool overlay_ready_ = false; ///< overlay_ holds the latest frame with the cache view
  std::shared_ptr<gpu::Context> device_; ///< share_device's
  /// Keeps the active tracer's frames on device_ when there is one and the cache view is off.
  void keep_frames_on_device();
  Framebuffer overlay_{1, 1};
  CacheViewCounts cache_view_counts_;
};

/// Projects a world point to pixel coordinates (x right, y down) of a width × height frame;
/// empty behind the camera.
[[nodiscard]] std::optional<dvec2> project(const Camera& camera, std::uint32_t width,
                                           std::uint32_t height, const dvec3& world);

} // namespace specula::editor
