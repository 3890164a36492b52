#include "editor/core/editor_session.h"

#include "editor/core/fields.h"
#include "specula/cache/ray_cache.h"
#include "specula/core/error.h"
#include "specula/image/image_io.h"
#include "specula/render/resolution_governor.h"
#include "specula/scene/hierarchy.h"
#include "specula/scene/json_scene.h"
#include "specula/trace/camera_rays.h"

#include <algorithm>
#include <cmath>

namespace specula::editor {

namespace {

bool same(const Mesh& a, const Mesh& b) {
  return a.geometry == b.geometry && a.source == b.source &&
         a.deformed_positions == b.deformed_positions && a.deformed_tick == b.deformed_tick &&
         a.deformed_time == b.deformed_time && a.deformed_normals == b.deformed_normals;
}
bool same(const Name& a, const Name& b) { return a.value == b.value; }
template <typename T>
bool same(const T& a, const T& b) {
  return a == b;
}

template <typename T>
bool same_optional(const std::optional<T>& a, const std::optional<T>& b) {
  return a.has_value() == b.has_value() && (!a || same(*a, *b));
}

/// Makes e's T match `want`, writing only when it differs (so unchanged components keep their
/// pool versions and the scene layer does no work for them).
template <typename T>
void sync_component(ecs::Registry& r, ecs::Entity e, const std::optional<T>& want) {
  const T* have = r.try_get<T>(e);
  if (want) {
    if (have == nullptr || !same(*have, *want)) r.emplace_or_replace<T>(e, *want);
  } else if (have != nullptr) {
    r.remove<T>(e);
  }
}

dvec3 world_position(ecs::Registry& r, ecs::Entity e) {
  if (const auto* w = r.try_get<WorldTransform>(e)) return dvec3(w->world_from_object[3]);
  if (const auto* t = r.try_get<Transform>(e)) return t->translation;
  return dvec3(0.0);
}

/// The linear part of e's parent's world matrix (identity without a parent): turns world
/// directions into e's local (parent-space) ones through its inverse.
dmat3 parent_linear(ecs::Registry& r, ecs::Entity e) {
  if (const auto* p = r.try_get<Parent>(e))
    if (const auto* w = r.try_get<WorldTransform>(p->entity)) return dmat3(w->world_from_object);
  return dmat3(1.0);
}

} // namespace

std::optional<dvec2> project(const Camera& camera, std::uint32_t width, std::uint32_t height,
                             const dvec3& world) {
  // The inverse of CameraRays::ray, in double: pixel (x, y)'s centre is (x + 0.5, y + 0.5).
  const dvec3 forward = glm::normalize(camera.look_at - camera.position);
  dvec3 r = glm::cross(forward, dvec3(camera.up));
  if (glm::length(r) < 1e-6)
    r = glm::cross(forward, std::abs(forward.y) < 0.9 ? dvec3(0, 1, 0) : dvec3(1, 0, 0));
  r = glm::normalize(r);
  const dvec3 u = glm::normalize(glm::cross(r, forward));
  const double tan_half = std::tan(0.5 * double(camera.vertical_fov));
  const double aspect = double(width) / double(height);
  const dvec3 v = world - camera.position;
  const double z = glm::dot(v, forward);
  if (!(z > 0.0)) return std::nullopt;
  const double sx = glm::dot(v, r) / (z * tan_half * aspect);
  const double sy = glm::dot(v, u) / (z * tan_half);
  return dvec2((sx + 1.0) * 0.5 * double(width), (1.0 - sy) * 0.5 * double(height));
}

EditorSession::EditorSession(const std::filesystem::path& scene_path, ViewSettings view)
    : scene_(load_scene(scene_path)), view_(std::move(view)) {
  scene_.registry.each_entity([&](ecs::Entity e) { assign_id(e); });
  prepare();
}

void EditorSession::prepare() {
  overlay_ready_ = false; // the overlay showed the previous job's frame
  if (!view_.max_depth) view_.max_depth = scene_.settings.max_depth;
  if (*view_.max_depth > kMaxTraceDepth)
    throw Error("--depth", "must be at most " + std::to_string(kMaxTraceDepth));
  RenderJob job;
  job.backend = view_.backend;
  job.settings.mode = view_.mode;
  job.settings.max_depth = *view_.max_depth;
  job.settings.background = scene_.settings.background;
  job.settings.threads = view_.threads;
  job.image = Framebuffer(view_.width, view_.height);
  job.cache = view_.cache;
  job.gpu.device = device_;
  prepare_rendering(scene_.registry, std::move(job));
  keep_frames_on_device();
}

void EditorSession::keep_frames_on_device() {
  specula::keep_frames_on_device(*scene_.registry.resource<ActiveTracer>().tracer,
                                 device_ != nullptr && !cache_view_);
}

void EditorSession::share_device(std::shared_ptr<gpu::Context> device) {
  device_ = std::move(device);
  scene_.registry.resource<RenderJob>().gpu.device = device_;
  const RenderJob& job = scene_.registry.resource<RenderJob>();
  if (tracer_device(*scene_.registry.resource<ActiveTracer>().tracer))
    set_backend(job.backend); // a tracer on the new device
  else
    keep_frames_on_device();
}

const gpu::DeviceFrame* EditorSession::device_frame() const {
  if (overlay_ready_) return nullptr;
  auto& r = const_cast<ecs::Registry&>(scene_.registry); // read only
  return specula::device_frame(*r.resource<ActiveTracer>().tracer);
}

EditorId EditorSession::assign_id(ecs::Entity e) {
  const EditorId id = next_id_++;
  entities_[id] = e;
  ids_[e.index] = id;
  return id;
}

ecs::Entity EditorSession::entity(EditorId id) const {
  const auto it = entities_.find(id);
  return it == entities_.end() ? ecs::null_entity : it->second;
}

EditorId EditorSession::id_of(ecs::Entity e) const {
  const auto it = ids_.find(e.index);
  if (it == ids_.end() || !scene_.registry.valid(e) || entity(it->second) != e) return kNoId;
  return it->second;
}

// --- frames
// ---------------------------------------------------------------------------------------

void EditorSession::set_render_scale(float scale) { render_scale_ = scale; }

void EditorSession::tick(double dt) {
  if (auto* caches = scene_.registry.try_resource<cache::RayCaches>(); caches && caches->store)
    caches->store->set_log_lookups(cache_view_);
  Framebuffer& image = scene_.registry.resource<RenderJob>().image;
  const auto [w, h] = ResolutionGovernor::scaled(view_.width, view_.height, render_scale_);
  if (image.width() != w || image.height() != h) image = Framebuffer(w, h);
  schedule_.tick(scene_.registry, dt);
  FrameSample s;
  if (const auto* t = scene_.registry.try_resource<FrameTimings>()) {
    s.ms = t->ms;
    s.system_ms = t->system_ms;
  }
  const RenderJob& job = scene_.registry.resource<RenderJob>();
  if (job.last.trace_ms > 0.0)
    s.rays_per_second = double(job.last.rays.total()) / (job.last.trace_ms * 1e-3);
  history_.push_back(std::move(s));
  if (history_.size() > kHistory) history_.pop_front();
  overlay_ready_ = false;
  cache_view_counts_ = CacheViewCounts{};
  if (!cache_view_) return;
  const auto* caches = scene_.registry.try_resource<cache::RayCaches>();
  const std::optional<Camera> cam = active_camera(scene_.registry);
  if (caches == nullptr || !caches->store || !cam) return;
  overlay_ = job.image;
  cache_view_counts_ =
      tint_cache_view(overlay_, *cam, scene_.registry.resource<SceneLayer>(),
                      *scene_.registry.resource<ActiveTracer>().tracer, *caches->store);
  overlay_ready_ = true;
}

const Framebuffer& EditorSession::frame() const {
  if (overlay_ready_) return overlay_;
  // Registry lookups are non-const (pools are made on demand); the image is written only by a
  // pending device frame's readback, which leaves it as the frame rendered.
  auto& r = const_cast<ecs::Registry&>(scene_.registry);
  RenderJob& job = r.resource<RenderJob>();
  if (const Tracer& tracer = *r.resource<ActiveTracer>().tracer; specula::device_frame(tracer))
    read_back_frame(tracer, job.image);
  return job.image;
}

std::pair<std::uint32_t, std::uint32_t> EditorSession::frame_size() const {
  if (overlay_ready_) return {overlay_.width(), overlay_.height()};
  const Framebuffer& image =
      const_cast<ecs::Registry&>(scene_.registry).resource<RenderJob>().image;
  return {image.width(), image.height()};
}

void EditorSession::set_cache_view(bool on) {
  cache_view_ = on;
  keep_frames_on_device();
  if (!on) {
    overlay_ready_ = false;
    cache_view_counts_ = CacheViewCounts{};
  }
}

// --- render settings
// ------------------------------------------------------------------------------

void EditorSession::set_backend(const std::string& backend) {
  RenderJob& job = scene_.registry.resource<RenderJob>();
  TracerOptions options;
  options.packet_width = job.packet_width;
  options.kind = scene_kind(scene_.registry);
  options.gpu = job.gpu;
  std::unique_ptr<Tracer> tracer = make_tracer(backend, options);
  // The layer stays: the new tracer's first update gets the whole scene (delta_since), now, so
  // that picking works before the next tick.
  if (const SceneLayer* layer = scene_.registry.try_resource<SceneLayer>();
      layer != nullptr && layer->syncs() > 0)
    tracer->update(*layer);
  job.backend = std::string(tracer->name());
  view_.backend = backend;
  Tracer& previous = *scene_.registry.resource<ActiveTracer>().tracer;
  if (specula::device_frame(previous)) read_back_frame(previous, job.image); // goes with it
  scene_.registry.resource<ActiveTracer>().tracer = std::move(tracer);
  keep_frames_on_device();
}

void EditorSession::set_mode(TraceMode mode) {
  view_.mode = mode;
  scene_.registry.resource<RenderJob>().settings.mode = mode;
}

void EditorSession::set_max_depth(std::uint32_t depth) {
  if (depth > kMaxTraceDepth)
    throw Error("depth", "must be at most " + std::to_string(kMaxTraceDepth) + ", got " +
                             std::to_string(depth));
  view_.max_depth = depth;
  scene_.registry.resource<RenderJob>().settings.max_depth = depth;
}

void EditorSession::set_cache(const cache::CacheSettings& cache) {
  view_.cache = cache;
  view_.backend = scene_.registry.resource<RenderJob>().backend;
  prepare();
}

// --- selection
// ------------------------------------------------------------------------------------

std::optional<ecs::Entity> EditorSession::click(std::uint32_t x, std::uint32_t y) {
  const auto [width, height] = frame_size();
  if (x >= width || y >= height)
    throw Error("click", "pixel (" + std::to_string(x) + ", " + std::to_string(y) +
                             ") lies outside the " + std::to_string(width) + "x" +
                             std::to_string(height) + " frame");
  const SceneLayer& layer = scene_.registry.resource<SceneLayer>();
  if (layer.syncs() == 0) throw Error("click", "no frame has been rendered yet");
  const std::optional<Camera> cam = active_camera(scene_.registry);
  if (!cam) throw Error("click", "the scene has no camera");
  // The same camera ray the frame traced, through the active tracer: no separate picking path.
  const Ray ray = CameraRays(*cam, width, height, layer.render_origin()).ray(x, y);
  Hit hit;
  scene_.registry.resource<ActiveTracer>().tracer->intersect({&ray, 1}, {&hit, 1});
  selected_ = kNoId;
  if (!hit.hit() || !layer.tables().live(hit.instance)) return std::nullopt;
  const ecs::Entity e = layer.tables().entity(hit.instance);
  selected_ = id_of(e);
  return selected();
}

void EditorSession::select(ecs::Entity e) {
  const EditorId id = id_of(e);
  if (id == kNoId) throw Error("select", "not a live entity");
  selected_ = id;
}

void EditorSession::select_by_name(std::string_view name) {
  ecs::Entity best = ecs::null_entity;
  scene_.registry.view<Name>().each([&](ecs::Entity e, const Name& n) {
    if (n.value == name && (best == ecs::null_entity || e.index < best.index)) best = e;
  });
  if (best == ecs::null_entity)
    throw Error("select", "no entity named \"" + std::string(name) + "\"");
  select(best);
}

std::optional<ecs::Entity> EditorSession::selected() const {
  const ecs::Entity e = entity(selected_);
  if (selected_ == kNoId || !scene_.registry.valid(e)) return std::nullopt;
  return e;
}

// --- edits
// ----------------------------------------------------------------------------------------

EntitySnapshot EditorSession::snapshot(ecs::Entity e) const {
  // The registry's lookups are non-const (pools are created on demand); nothing is written.
  auto& r = const_cast<ecs::Registry&>(scene_.registry);
  EntitySnapshot s;
  const auto take = [&](auto& slot) {
    using T = typename std::remove_reference_t<decltype(slot)>::value_type;
    if (const T* c = r.try_get<T>(e)) slot = *c;
  };
  take(s.name);
  take(s.transform);
  take(s.mesh);
  take(s.material);
  take(s.kinematics);
  // An entity a drag made hierarchical for the gesture (unfreeze_for_drag) keeps its own class.
  if (!drag_kinematics_.empty())
    if (const EditorId id = id_of(e); id != kNoId)
      for (const auto& [switched, own] : drag_kinematics_)
        if (switched == id) s.kinematics = own;
  take(s.light);
  take(s.camera);
  take(s.camera_path);
  take(s.ray_cache_cube);
  take(s.animation);
  if (const Parent* p = r.try_get<Parent>(e)) s.parent = id_of(p->entity);
  s.default_tag = r.has<DefaultTag>(e);
  return s;
}

void EditorSession::write(EditorId id, const EntitySnapshot& state, const EntitySnapshot* other) {
  ecs::Registry& r = scene_.registry;
  const ecs::Entity e = entity(id);
  // With `other` (the command's other side), only what the command changed is written: undoing
  // a Material edit leaves the Transform an animation has moved since where it is.
  const auto take = [&](const auto& member) {
    const auto& want = state.*member;
    if (other == nullptr || !same_optional(want, other->*member)) sync_component(r, e, want);
  };
  take(&EntitySnapshot::name);
  take(&EntitySnapshot::transform);
  take(&EntitySnapshot::mesh);
  take(&EntitySnapshot::material);
  take(&EntitySnapshot::kinematics);
  take(&EntitySnapshot::light);
  take(&EntitySnapshot::camera);
  take(&EntitySnapshot::camera_path);
  take(&EntitySnapshot::ray_cache_cube);
  take(&EntitySnapshot::animation);
  if (other == nullptr || state.parent != other->parent) {
    std::optional<Parent> parent;
    if (state.parent) parent = Parent{entity(*state.parent)};
    const Parent* have = r.try_get<Parent>(e);
    if (parent && (have == nullptr || have->entity != parent->entity))
      r.emplace_or_replace<Parent>(e, *parent);
    else if (!parent && have != nullptr)
      r.remove<Parent>(e);
  }
  if (state.default_tag && !r.has<DefaultTag>(e))
    r.emplace<DefaultTag>(e);
  else if (!state.default_tag)
    r.remove<DefaultTag>(e);
}

void EditorSession::apply(const Command& command, bool forward) {
  // Two passes, so that the order of a command's changes never matters: entities come and go
  // first, then components (a Parent may name an entity the same command recreates).
  ecs::Registry& r = scene_.registry;
  for (const Change& c : command) {
    const auto& state = forward ? c.after : c.before;
    const ecs::Entity e = entity(c.id);
    const bool live = e != ecs::null_entity && r.valid(e);
    if (state && !live) {
      const ecs::Entity made = r.create();
      entities_[c.id] = made;
      ids_[made.index] = c.id;
    } else if (!state && live) {
      r.destroy(e);
      entities_.erase(c.id);
    }
  }
  for (const Change& c : command) {
    const auto& state = forward ? c.after : c.before;
    const auto& other = forward ? c.before : c.after;
    if (state) write(c.id, *state, other ? &*other : nullptr);
  }
}

void EditorSession::execute(Command command) {
  gesture_merges_ = false;
  apply(command, true);
  undo_.push_back(std::move(command));
  redo_.clear();
}

bool EditorSession::undo() {
  gesture_merges_ = false;
  restore_drag_kinematics();
  if (undo_.empty()) return false;
  apply(undo_.back(), false);
  redo_.push_back(std::move(undo_.back()));
  undo_.pop_back();
  return true;
}

bool EditorSession::redo() {
  gesture_merges_ = false;
  restore_drag_kinematics();
  if (redo_.empty()) return false;
  apply(redo_.back(), true);
  undo_.push_back(std::move(redo_.back()));
  redo_.pop_back();
  return true;
}

void EditorSession::edit(ecs::Entity e, const std::function<void(EntitySnapshot&)>& change) {
  const EditorId id = id_of(e);
  if (id == kNoId) throw Error("edit", "not a live entity");
  EntitySnapshot before = snapshot(e);
  EntitySnapshot after = before;
  change(after);
  Command step{Change{id, std::move(before), std::move(after)}};
  if (gesture_merges_ && !undo_.empty() && undo_.back().size() == 1 &&
      undo_.back().front().id == id && undo_.back().front().after) {
    // The gesture's step keeps its first "before" and takes this edit's "after".
    apply(step, true);
    undo_.back().front().after = std::move(step.front().after);
    redo_.clear();
    return;
  }
  execute(std::move(step));
  gesture_merges_ = gesture_;
}

void EditorSession::begin_gesture() {
  restore_drag_kinematics();
  gesture_ = true;
  gesture_merges_ = false;
}

void EditorSession::end_gesture() {
  gesture_ = gesture_merges_ = false;
  restore_drag_kinematics();
}

void EditorSession::unfreeze_for_drag(ecs::Entity e) {
  ecs::Registry& r = scene_.registry;
  for (const ecs::Entity x : subtree(e)) {
    const Kinematics* k = r.try_get<Kinematics>(x);
    if (k != nullptr && k->type != Kinematics::Type::Static) continue;
    if (!r.has<Mesh>(x)) continue; // nothing to trace: no structure to spare
    const EditorId id = id_of(x);
    drag_kinematics_.emplace_back(id, k != nullptr ? std::optional<Kinematics>(*k) : std::nullopt);
    r.emplace_or_replace<Kinematics>(x, Kinematics{Kinematics::Type::Hierarchical});
  }
}

void EditorSession::restore_drag_kinematics() {
  ecs::Registry& r = scene_.registry;
  for (const auto& [id, own] : drag_kinematics_) {
    const ecs::Entity x = entity(id);
    if (x == ecs::null_entity) continue; // deleted meanwhile
    if (own)
      r.emplace_or_replace<Kinematics>(x, *own);
    else
      r.remove<Kinematics>(x);
  }
  drag_kinematics_.clear();
  drag_checked_ = kNoId;
}

dvec2 EditorSession::screen_axis(ecs::Entity e, int axis) const {
  if (axis < 0 || axis > 2) throw Error("drag", "axis must be x, y or z");
  auto& r = const_cast<ecs::Registry&>(scene_.registry); // read only
  const std::optional<Camera> cam = active_camera(r);
  if (!cam) throw Error("drag", "the scene has no camera");
  const dvec3 p = world_position(r, e);
  dvec3 unit(0.0);
  unit[axis] = 1.0;
  const auto [width, height] = frame_size();
  const auto a = project(*cam, width, height, p);
  const auto b = project(*cam, width, height, p + unit);
  if (!a || !b) throw Error("drag", "the handle lies behind the camera");
  return *b - *a;
}

void EditorSession::drag(GizmoMode mode, int axis, dvec2 screen_delta) {
  const std::optional<ecs::Entity> e = selected();
  if (!e) throw Error("drag", "nothing is selected");
  if (!scene_.registry.has<Transform>(*e)) throw Error("drag", "the selection has no Transform");
  const dvec2 s = screen_axis(*e, axis);
  const double len2 = glm::dot(s, s);
  dvec3 unit(0.0);
  unit[axis] = 1.0;
  const dmat3 local_from_world = glm::inverse(parent_linear(scene_.registry, *e));
  // Before the first move of a gesture, so that no frame sees a static entity move (the edit's
  // snapshots still hold its own kinematics).
  if (gesture_ && drag_checked_ != id_of(*e)) {
    drag_checked_ = id_of(*e);
    unfreeze_for_drag(*e);
  }
  edit(*e, [&](EntitySnapshot& snap) {
    Transform& t = *snap.transform;
    if (mode == GizmoMode::Rotate) {
      const double angle = screen_delta.x * kRotateRadiansPerPixel;
      const vec3 local_axis = vec3(glm::normalize(local_from_world * unit));
      t.rotation = glm::normalize(glm::angleAxis(float(angle), local_axis) * t.rotation);
      return;
    }
    if (len2 < 1e-12) throw Error("drag", "the axis points straight at the camera");
    const double amount = glm::dot(screen_delta, s) / len2; // world units along the axis
    if (mode == GizmoMode::Translate) {
      t.translation += local_from_world * (amount * unit);
      if (!is_finite(t.translation) || !in_range(t.translation))
        throw Error("drag", std::string("the entity would leave ") + kCoordinateRangeText);
    } else {
      const float scaled = t.scale[axis] + float(amount);
      if (!(scaled > 0.0f) || !std::isfinite(scaled))
        throw Error("drag", "the scale would not stay positive");
      t.scale[axis] = scaled;
    }
  });
}

void EditorSession::set_field(ecs::Entity e, std::string_view path, std::string_view value) {
  restore_drag_kinematics(); // a field edit sees (and may set) the entities' own kinematics
  edit(e, [&](EntitySnapshot& s) { editor::set_field(s, path, value); });
}

ecs::Entity EditorSession::add_entity(EntitySnapshot s) {
  const EditorId id = next_id_++;
  execute({Change{id, std::nullopt, std::move(s)}});
  selected_ = id;
  return entity(id);
}

ecs::Entity EditorSession::add_mesh_entity(const MeshSource& source, const std::string& name) {
  EntitySnapshot s;
  s.mesh = Mesh{meshes_.get(source, scene_.source.parent_path()), source, {}, 0, 0.0f};
  s.name = Name{name};
  s.transform = Transform{};
  s.material = Material{};
  // Free: an entity made in the editor is expected to move (no static rebuild when dragged).
  s.kinematics = Kinematics{Kinematics::Type::Free};
  return add_entity(std::move(s));
}

ecs::Entity EditorSession::add_primitive(const std::string& primitive, const std::string& name) {
  MeshSource source;
  source.kind = MeshSource::Kind::Primitive;
  source.primitive = primitive;
  return add_mesh_entity(source, name);
}

ecs::Entity EditorSession::add_mesh_file(const std::filesystem::path& file,
                                         const std::string& name) {
  MeshSource source;
  source.kind = MeshSource::Kind::File;
  source.path = file.generic_string();
  return add_mesh_entity(source, name);
}

std::vector<ecs::Entity> EditorSession::subtree(ecs::Entity root) {
  std::vector<ecs::Entity> out{root};
  std::vector<std::pair<ecs::Entity, ecs::Entity>> links; // (child, parent)
  scene_.registry.view<Parent>().each(
      [&](ecs::Entity e, const Parent& p) { links.emplace_back(e, p.entity); });
  for (std::size_t i = 0; i < out.size(); ++i)
    for (const auto& [child, parent] : links)
      if (parent == out[i] && std::find(out.begin(), out.end(), child) == out.end())
        out.push_back(child);
  return out;
}

void EditorSession::remove(ecs::Entity e) {
  if (id_of(e) == kNoId) throw Error("delete", "not a live entity");
  restore_drag_kinematics();
  const std::vector<ecs::Entity> doomed = subtree(e);
  std::size_t cameras = 0, doomed_cameras = 0;
  scene_.registry.view<Camera>().each([&](ecs::Entity c, const Camera&) {
    ++cameras;
    if (std::find(doomed.begin(), doomed.end(), c) != doomed.end()) ++doomed_cameras;
  });
  // Every frame needs a camera (render_system): the last one stays.
  if (doomed_cameras > 0 && doomed_cameras == cameras)
    throw Error("delete", "the scene's last camera cannot be deleted");
  Command command;
  for (const ecs::Entity x : doomed) command.push_back(Change{id_of(x), snapshot(x), {}});
  execute(std::move(command));
}

void EditorSession::reparent(ecs::Entity e, ecs::Entity parent) {
  if (id_of(e) == kNoId) throw Error("reparent", "not a live entity");
  if (parent != ecs::null_entity) {
    if (id_of(parent) == kNoId) throw Error("reparent", "the new parent is not a live entity");
    if (!scene_.registry.has<Transform>(parent))
      throw Error("reparent", "the new parent has no Transform");
    for (ecs::Entity p = parent; p != ecs::null_entity;) {
      if (p == e)
        throw Error("reparent", entity_label(scene_.registry, parent) + " is " +
                                    entity_label(scene_.registry, e) +
                                    " or lies below it: the hierarchy would form a cycle");
      const Parent* up = scene_.registry.try_get<Parent>(p);
      p = up != nullptr ? up->entity : ecs::null_entity;
    }
  }
  edit(e, [&](EntitySnapshot& s) {
    if (parent == ecs::null_entity)
      s.parent.reset();
    else
      s.parent = id_of(parent);
  });
}

// --- camera
// ---------------------------------------------------------------------------------------

Camera EditorSession::camera() {
  const std::optional<Camera> cam = active_camera(scene_.registry);
  if (!cam) throw Error("camera", "the scene has no camera");
  return *cam;
}

void EditorSession::set_camera(const Camera& camera) {
  // active_camera's entity: the live Camera with the lowest slot index.
  ecs::Entity best = ecs::null_entity;
  scene_.registry.view<Camera>().each([&](ecs::Entity e, const Camera&) {
    if (best == ecs::null_entity || e.index < best.index) best = e;
  });
  if (best == ecs::null_entity) throw Error("camera", "the scene has no camera");
  scene_.registry.patch<Camera>(best, [&](Camera& c) { c = camera; });
}

void EditorSession::frame_selected() {
  const std::optional<ecs::Entity> e = selected();
  if (!e) return;
  ecs::Registry& r = scene_.registry;
  dvec3 centre = world_position(r, *e);
  double radius = 1.0;
  const Mesh* mesh = r.try_get<Mesh>(*e);
  const WorldTransform* w = r.try_get<WorldTransform>(*e);
  if (mesh != nullptr && mesh->geometry && w != nullptr) {
    const Aabb b = mesh->geometry->bounds();
    if (!b.empty()) {
      const DAabb world = DAabb::transformed(b, w->world_from_object);
      centre = 0.5 * (world.min + world.max);
      radius = std::max(0.5 * glm::length(world.max - world.min), 1e-3);
    }
  }
  Camera c = camera();
  const dvec3 back = glm::normalize(c.position - c.look_at);
  c.look_at = centre;
  c.position = centre + back * (radius / std::sin(0.5 * double(c.vertical_fov)));
  set_camera(c);
}

// --- files
// ----------------------------------------------------------------------------------------

void EditorSession::save(const std::filesystem::path& path) {
  restore_drag_kinematics(); // the file holds the entities' own kinematics
  save_json_scene(scene_, path);
}

void EditorSession::screenshot(const std::filesystem::path& path) const {
  write_png(frame(), path);
}

Framebuffer EditorSession::render_uncached() {
  ecs::Registry& r = scene_.registry;
  const RenderJob& job = r.resource<RenderJob>();
  RenderJob reference;
  reference.backend = job.backend;
  reference.settings = job.settings;
  reference.accumulate = job.accumulate;
  reference.image = Framebuffer(job.image.width(), job.image.height());
  (void)render_job_frame(reference, *r.resource<ActiveTracer>().tracer, r.resource<SceneLayer>(),
                         camera());
  return std::move(reference.image);
}

} // namespace specula::editor
