#include "specula/render/scene_layer.h"

#include "specula/core/error.h"
#include "specula/core/log.h"
#include "specula/scene/components/animation.h"
#include "specula/scene/components/kinematics.h"
#include "specula/scene/components/light.h"
#include "specula/scene/components/material.h"
#include "specula/scene/components/mesh.h"
#include "specula/scene/components/parent.h"
#include "specula/scene/components/world_transform.h"
#include "specula/scene/hierarchy.h"
#include "specula/scene/kinematics_rules.h"
#include "specula/scene/scene.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <unordered_set>

namespace specula {
namespace {

std::uint32_t kinematics_code(Kinematics::Type type) {
  switch (type) {
  case Kinematics::Type::Static:
    return gpu::kKinematicsStatic;
  case Kinematics::Type::Hierarchical:
    return gpu::kKinematicsHierarchical;
  case Kinematics::Type::Free:
    return gpu::kKinematicsFree;
  }
  return gpu::kKinematicsStatic;
}

gpu::GpuMaterial to_gpu(const Material& m) {
  gpu::GpuMaterial g{};
  g.base_color = m.base_color;
  g.ior = m.ior;
  g.emission = m.emission;
  g.reflectivity = m.reflectivity;
  g.transmission = m.transmission;
  g.roughness = m.roughness;
  return g;
}

gpu::GpuLight to_gpu(const Light& l, const dmat4& world_from_object, const dvec3& render_origin) {
  gpu::GpuLight g{};
  g.type = l.type == Light::Type::Point         ? gpu::kLightPoint
           : l.type == Light::Type::Directional ? gpu::kLightDirectional
                                                : gpu::kLightSpot;
  g.position = vec3(dvec3(world_from_object[3]) - render_origin);
  const vec3 forward = -vec3(dvec3(world_from_object[2]));
  g.direction = glm::length(forward) > 0.0f ? glm::normalize(forward) : vec3(0, 0, -1);
  g.intensity = l.color * l.intensity;
  g.range = l.range;
  g.cos_inner = std::cos(l.inner_cone);
  g.cos_outer = std::cos(l.outer_cone);
  return g;
}

template <typename T>
bool same_bytes(const T& a, const T& b) {
  return std::memcmp(&a, &b, sizeof(T)) == 0;
}

Aabb bounds_of(const vec3* p, std::size_t n) {
  Aabb b;
  for (std::size_t i = 0; i < n; ++i) b.grow(p[i]);
  return b;
}

/// Throws when a mesh entity's world-space extent leaves the representable range (a scale times
/// vertex coordinates, an animation): an error naming the entity, never an abort in a tracer.
void check_extent(ecs::Registry& registry, ecs::Entity e, const DAabb& world) {
  if (in_range(world.min) && in_range(world.max)) return;
  throw Error("scene", entity_label(registry, e) + " extends from " + format_position(world.min) +
                           " to " + format_position(world.max) + ", outside " +
                           kCoordinateRangeText);
}

bool deforms(ecs::Registry& registry, ecs::Entity e, const Mesh& mesh) {
  if (!mesh.deformed_positions.empty()) return true;
  const Animation* a = registry.try_get<Animation>(e);
  return a != nullptr && !a->vertices.empty();
}

} // namespace

std::optional<std::uint32_t> SceneLayer::instance_of(ecs::Entity entity) const {
  const auto it = slot_of_entity_.find(entity.index);
  if (it == slot_of_entity_.end() || slots_[it->second].entity != entity) return std::nullopt;
  return it->second;
}

const SceneDelta& SceneLayer::sync(ecs::Registry& registry) {
  delta_ = SceneDelta{};
  stats_ = SceneLayerStats{};
  static_moved_ = false;
  // The render origin first: every transform this sync writes is relative to it.
  const bool rebased = update_render_origin(registry);
  const TransformChanges* changes = registry.try_resource<TransformChanges>();
  const bool membership_changed = syncs_ == 0 || registry.version<Mesh>() != version_mesh_ ||
                                  registry.version<WorldTransform>() != version_transform_ ||
                                  registry.version<Kinematics>() != version_kinematics_ ||
                                  registry.version<Animation>() != version_animation_ ||
                                  registry.version<Parent>() != version_parent_;
  const std::uint64_t sequence = changes != nullptr ? changes->sequence : 0;
  // The moved list covers everything since the last sync only if exactly one transform update
  // ran in between (none: nothing moved).
  const bool moved_list_complete = changes != nullptr && (sequence == transform_sequence_ + 1 ||
                                                          sequence == transform_sequence_);
  const bool has_new_moves = moved_list_complete && sequence == transform_sequence_ + 1;
  if (membership_changed || !moved_list_complete) {
    full_scan(registry, has_new_moves ? &changes->moved : nullptr);
  } else if (has_new_moves) {
    apply_moved(registry, changes->moved);
  }
  if (rebased) rebase_instances(registry);
  apply_deformations(registry);
  if (stats_.full_scans > 0 || registry.version<Material>() != version_material_)
    refresh_materials(registry);
  refresh_lights(registry);

  if (delta_.static_rebuilt) {
    if (static_moved_)
      log_warning("a static entity moved: rebuilding the static structure (mark moving entities "
                  "'hierarchical' or 'free')");
    relayout(registry, true);
  } else if (const std::size_t garbage = tables_.positions.size() - live_vertices_;
             garbage > std::max<std::size_t>(live_vertices_, 1u << 16) ||
             dropped_normals_ >
                 std::max<std::size_t>(tables_.normals.size() - dropped_normals_, 1u << 16)) {
    relayout(registry, false);
  }
  // Mesh records freed in this sync become reusable only now: a consumer removes them after
  // adding the new ones (SceneDelta's order), so a record must not be both in one delta.
  for (const std::uint32_t r : delta_.meshes_removed) free_meshes_.push_back(r);
  if (syncs_ == 0 || !delta_.empty()) emitters_.build(tables_);

  version_mesh_ = registry.version<Mesh>();
  version_transform_ = registry.version<WorldTransform>();
  version_kinematics_ = registry.version<Kinematics>();
  version_animation_ = registry.version<Animation>();
  version_parent_ = registry.version<Parent>();
  version_material_ = registry.version<Material>();
  transform_sequence_ = sequence;
  ++syncs_;
  changed_before_ = changed_;
  if (syncs_ == 1 || !delta_.empty()) changed_ = syncs_;
  stats_.static_instances = std::uint32_t(tables_.static_instances.size());
  stats_.static_triangles = tables_.static_triangle_count;
  stats_.dynamic_instances = std::uint32_t(slot_of_entity_.size()) - stats_.static_instances;
  return delta_;
}

bool SceneLayer::update_render_origin(ecs::Registry& registry) {
  const std::optional<Camera> camera = active_camera(registry);
  if (!camera) return false; // no camera: the origin stays where it is
  if (!in_range(camera->position) || !in_range(camera->look_at))
    throw Error("scene", "the camera is at " + format_position(camera->position) + " looking at " +
                             format_position(camera->look_at) + ", outside " +
                             kCoordinateRangeText);
  if (glm::length(camera->position - render_origin_) <= kRebaseDistance) return false;
  render_origin_ = camera->position;
  if (syncs_ == 0) return false; // the first sync builds everything relative to it anyway
  ++stats_.rebases;
  ++rebases_;
  return true;
}

void SceneLayer::rebase_instances(ecs::Registry& registry) {
  // Every instance's render-space transform changed. Those this sync already added or moved are
  // current; the rest are rewritten and reported as moved, and the static set is baked again.
  std::vector<bool> done(slots_.size(), false);
  for (const std::uint32_t slot : delta_.instances_added) done[slot] = true;
  for (const std::uint32_t slot : delta_.instances_moved) done[slot] = true;
  for (std::uint32_t slot = 0; slot < slots_.size(); ++slot) {
    if (!tables_.live(slot)) continue;
    if ((tables_.instances[slot].flags & gpu::kInstanceStatic) != 0) {
      delta_.static_rebuilt = true;
      continue;
    }
    if (done[slot]) continue;
    write_transform(registry, slot,
                    registry.get<WorldTransform>(slots_[slot].entity).world_from_object);
    delta_.instances_moved.push_back(slot);
    ++stats_.instances_moved;
  }
  delta_.lights_changed = true; // refresh_lights compares the new positions anyway
}

void SceneLayer::full_scan(ecs::Registry& registry, const std::vector<ecs::Entity>* moved) {
  stats_.full_scans = 1;
  // What moved since the last sync: the transform system's list when it covers the whole time,
  // else every entity whose world transform changed in a later tick than the one last applied.
  std::unordered_set<std::uint32_t> moved_now;
  if (moved != nullptr)
    for (const ecs::Entity e : *moved) moved_now.insert(e.index);
  std::vector<bool> seen(slots_.size(), false);
  registry.view<Mesh, WorldTransform>().each([&](ecs::Entity e, const Mesh& mesh,
                                                 const WorldTransform& wt) {
    ++stats_.entities_visited;
    if (!mesh.geometry) return;
    const Kinematics* k = registry.try_get<Kinematics>(e);
    const Desired desired{
        &mesh.geometry, kinematics_code(k != nullptr ? k->type : inferred_kinematics(registry, e)),
        deforms(registry, e, mesh)};
    const bool desired_static = desired.kinematics == gpu::kKinematicsStatic && !desired.deforming;
    if (const auto it = slot_of_entity_.find(e.index); it != slot_of_entity_.end()) {
      const std::uint32_t slot = it->second;
      Slot& s = slots_[slot];
      const bool is_static = (tables_.instances[slot].flags & gpu::kInstanceStatic) != 0;
      if (s.entity == e && s.source == mesh.geometry.get() && is_static == desired_static &&
          s.deforming == desired.deforming) {
        seen[slot] = true;
        tables_.instances[slot].kinematics = desired.kinematics;
        if (moved != nullptr ? moved_now.contains(e.index) : wt.moved_tick != s.moved_tick) {
          if (is_static) {
            delta_.static_rebuilt = true;
            static_moved_ = true;
          } else {
            write_transform(registry, slot, wt.world_from_object);
            delta_.instances_moved.push_back(slot);
            ++stats_.instances_moved;
          }
          s.moved_tick = wt.moved_tick;
        }
        return;
      }
      remove_instance(slot);
    }
    add_instance(registry, e, desired);
    if (seen.size() < slots_.size()) seen.resize(slots_.size(), false);
    seen[slot_of_entity_.at(e.index)] = true;
  });
  for (std::uint32_t slot = 0; slot < seen.size(); ++slot)
    if (!seen[slot] && tables_.live(slot)) remove_instance(slot);
}

void SceneLayer::apply_moved(ecs::Registry& registry, const std::vector<ecs::Entity>& moved) {
  for (const ecs::Entity e : moved) {
    ++stats_.entities_visited;
    const std::optional<std::uint32_t> slot = instance_of(e);
    if (!slot) continue; // not a mesh entity (camera, light, group node)
    Slot& s = slots_[*slot];
    const WorldTransform& wt = registry.get<WorldTransform>(e);
    s.moved_tick = wt.moved_tick;
    if ((tables_.instances[*slot].flags & gpu::kInstanceStatic) != 0) {
      delta_.static_rebuilt = true;
      static_moved_ = true;
      continue;
    }
    write_transform(registry, *slot, wt.world_from_object);
    delta_.instances_moved.push_back(*slot);
    ++stats_.instances_moved;
  }
}

void SceneLayer::apply_deformations(ecs::Registry& registry) {
  for (const std::uint32_t slot : deforming_) {
    Slot& s = slots_[slot];
    const Mesh& mesh = registry.get<Mesh>(s.entity);
    if (mesh.deformed_tick == s.deformed_tick) continue;
    s.deformed_tick = mesh.deformed_tick;
    gpu::GpuMesh& record = tables_.meshes[tables_.instances[slot].mesh];
    const std::vector<vec3>& positions = mesh.positions();
    if (positions.size() != record.vertex_count)
      throw Error("scene", entity_label(registry, s.entity) + " deformed to " +
                               std::to_string(positions.size()) + " vertices, but its mesh has " +
                               std::to_string(record.vertex_count));
    std::copy(positions.begin(), positions.end(), tables_.positions.begin() + record.first_vertex);
    stats_.vertices_written += positions.size();
    write_deformed_normals(record, mesh);
    const Aabb b = bounds_of(positions.data(), positions.size());
    record.bounds_min = b.min;
    record.bounds_max = b.max;
    write_transform(registry, slot, s.world_from_object); // new world bounds
    delta_.instances_deformed.push_back(slot);
    ++stats_.instances_deformed;
  }
}

void SceneLayer::write_deformed_normals(gpu::GpuMesh& record, const Mesh& mesh) {
  const std::vector<vec3>& n = mesh.deformed_normals;
  if (n.size() != record.vertex_count) {
    // None sampled: its old range is left for compaction, and counted.
    if (record.first_normal != gpu::kNoIndex) dropped_normals_ += record.vertex_count;
    record.first_normal = gpu::kNoIndex;
    return;
  }
  if (record.first_normal == gpu::kNoIndex) {
    record.first_normal = std::uint32_t(tables_.normals.size());
    tables_.normals.resize(tables_.normals.size() + n.size());
  }
  std::copy(n.begin(), n.end(), tables_.normals.begin() + record.first_normal);
}

void SceneLayer::refresh_materials(ecs::Registry& registry) {
  for (std::uint32_t slot = 0; slot < slots_.size(); ++slot) {
    if (!tables_.live(slot)) continue;
    const Material* m = registry.try_get<Material>(slots_[slot].entity);
    const gpu::GpuMaterial g = to_gpu(m != nullptr ? *m : Material{});
    if (!same_bytes(g, tables_.materials[slot])) {
      tables_.materials[slot] = g;
      delta_.materials_changed = true;
    }
  }
}

void SceneLayer::refresh_lights(ecs::Registry& registry) {
  std::vector<gpu::GpuLight> lights;
  lights.reserve(tables_.lights.size());
  registry.view<Light, WorldTransform>().each([&](const Light& l, const WorldTransform& wt) {
    // A light in a Hidden subtree (its world transform collapsed to its origin) is off.
    if (dmat3(wt.world_from_object) == dmat3(0.0)) return;
    lights.push_back(to_gpu(l, wt.world_from_object, render_origin_));
  });
  if (lights.size() != tables_.lights.size() ||
      (!lights.empty() && std::memcmp(lights.data(), tables_.lights.data(),
                                      lights.size() * sizeof(gpu::GpuLight)) != 0)) {
    tables_.lights = std::move(lights);
    delta_.lights_changed = true;
  }
}

std::uint32_t SceneLayer::new_mesh_record() {
  if (!free_meshes_.empty()) {
    const std::uint32_t r = free_meshes_.back();
    free_meshes_.pop_back();
    return r;
  }
  tables_.meshes.emplace_back();
  return std::uint32_t(tables_.meshes.size() - 1);
}

std::uint32_t SceneLayer::acquire_shared_mesh(const std::shared_ptr<const TriangleMesh>& geometry) {
  SharedMesh& shared = shared_[geometry.get()];
  if (shared.record == gpu::kNoIndex) {
    const TriangleMesh& m = *geometry;
    shared.source = geometry;
    shared.record = new_mesh_record();
    gpu::GpuMesh record{};
    record.first_vertex = std::uint32_t(tables_.positions.size());
    record.vertex_count = std::uint32_t(m.positions.size());
    record.first_triangle = std::uint32_t(tables_.triangles.size());
    record.triangle_count = std::uint32_t(m.triangles.size());
    record.first_normal = gpu::kNoIndex;
    if (m.normals.size() == m.positions.size()) {
      record.first_normal = std::uint32_t(tables_.normals.size());
      tables_.normals.insert(tables_.normals.end(), m.normals.begin(), m.normals.end());
    }
    tables_.positions.insert(tables_.positions.end(), m.positions.begin(), m.positions.end());
    tables_.triangles.insert(tables_.triangles.end(), m.triangles.begin(), m.triangles.end());
    const Aabb b = bounds_of(m.positions.data(), m.positions.size());
    record.bounds_min = b.min;
    record.bounds_max = b.max;
    tables_.meshes[shared.record] = record;
    live_vertices_ += m.positions.size();
    stats_.vertices_written += m.positions.size();
    delta_.meshes_added.push_back(shared.record);
  }
  ++shared.users;
  return shared.record;
}

const SceneDelta& SceneLayer::delta_since(std::uint64_t applied) const {
  if (applied + 1 == syncs_) return delta_;
  if (whole_sync_ != syncs_) {
    whole_ = SceneDelta{};
    whole_.full = true;
    whole_.static_rebuilt = true;
    whole_.materials_changed = whole_.lights_changed = whole_.geometry_relocated = true;
    for (const auto& [source, mesh] : shared_) whole_.meshes_added.push_back(mesh.record);
    std::sort(whole_.meshes_added.begin(), whole_.meshes_added.end());
    for (std::uint32_t slot = 0; slot < tables_.instances.size(); ++slot)
      if (tables_.live(slot) && (tables_.instances[slot].flags & gpu::kInstanceStatic) == 0)
        whole_.instances_added.push_back(slot);
    whole_sync_ = syncs_;
  }
  return whole_;
}

void SceneLayer::release_shared_mesh(const TriangleMesh* source) {
  const auto it = shared_.find(source);
  if (it == shared_.end() || --it->second.users > 0) return;
  gpu::GpuMesh& record = tables_.meshes[it->second.record];
  live_vertices_ -= record.vertex_count;
  record = gpu::GpuMesh{};
  record.first_vertex = gpu::kNoIndex;
  delta_.meshes_removed.push_back(it->second.record);
  shared_.erase(it);
}

mat4 SceneLayer::render_from(const dmat4& world_from_object) const {
  dmat4 m = world_from_object;
  m[3] -= dvec4(render_origin_, 0.0); // in double: the difference is small, then exact in float
  return mat4(m);
}

void SceneLayer::write_transform(ecs::Registry& registry, std::uint32_t slot,
                                 const dmat4& world_from_object) {
  slots_[slot].world_from_object = world_from_object;
  gpu::GpuInstance& inst = tables_.instances[slot];
  const gpu::GpuMesh& record = tables_.meshes[inst.mesh];
  const Aabb object{record.bounds_min, record.bounds_max};
  check_extent(registry, slots_[slot].entity, DAabb::transformed(object, world_from_object));
  const mat4 render_from_object = render_from(world_from_object);
  inst.world_from_object = render_from_object;
  const mat3 n = glm::transpose(glm::inverse(mat3(render_from_object)));
  for (int c = 0; c < 3; ++c) inst.normal_from_object[c] = vec4(n[c], 0.0f);
  const Aabb render = object.transformed(render_from_object);
  inst.world_bounds_min = render.min;
  inst.world_bounds_max = render.max;
}

void SceneLayer::add_instance(ecs::Registry& registry, ecs::Entity e, const Desired& d) {
  std::uint32_t slot;
  if (!free_slots_.empty()) {
    slot = free_slots_.back();
    free_slots_.pop_back();
  } else {
    slot = std::uint32_t(slots_.size());
    slots_.emplace_back();
    tables_.instances.emplace_back();
    tables_.materials.emplace_back();
  }
  const Mesh& mesh = registry.get<Mesh>(e);
  const WorldTransform& wt = registry.get<WorldTransform>(e);
  Slot& s = slots_[slot];
  s = Slot{};
  s.entity = e;
  s.source = mesh.geometry.get();
  s.deforming = d.deforming;
  s.moved_tick = wt.moved_tick;
  s.deformed_tick = mesh.deformed_tick;
  slot_of_entity_[e.index] = slot;

  gpu::GpuInstance& inst = tables_.instances[slot];
  inst = gpu::GpuInstance{};
  inst.material = slot;
  inst.entity_index = e.index;
  inst.entity_generation = e.generation;
  inst.kinematics = d.kinematics;
  const Material* m = registry.try_get<Material>(e);
  tables_.materials[slot] = to_gpu(m != nullptr ? *m : Material{});

  if (d.kinematics == gpu::kKinematicsStatic && !d.deforming) {
    // Baked into world space by relayout, which this sync runs.
    inst.mesh = new_mesh_record();
    tables_.meshes[inst.mesh] = gpu::GpuMesh{};
    inst.flags = gpu::kInstanceStatic | gpu::kInstanceIdentity;
    if (mesh.geometry->normals.size() == mesh.geometry->positions.size())
      inst.flags |= gpu::kInstanceSmooth;
    inst.world_from_object = mat4(1.0f);
    for (int c = 0; c < 3; ++c) inst.normal_from_object[c] = vec4(mat3(1.0f)[c], 0.0f);
    delta_.static_rebuilt = true;
    return;
  }

  s.shared_mesh = acquire_shared_mesh(*d.geometry);
  if (d.deforming) {
    // Its own vertex range (the shared triangles): rewritten in place when it deforms. The shared
    // mesh's vertex normals no longer match the positions: it has its own range of them when its
    // animation samples normals too (write_deformed_normals), else shading uses the geometric
    // normal.
    const gpu::GpuMesh shared = tables_.meshes[s.shared_mesh];
    const std::vector<vec3>& positions = mesh.positions();
    if (positions.size() != shared.vertex_count)
      throw Error("scene", entity_label(registry, e) + " has " + std::to_string(positions.size()) +
                               " deformed vertices, but its mesh has " +
                               std::to_string(shared.vertex_count));
    inst.mesh = new_mesh_record();
    gpu::GpuMesh own = shared;
    own.first_vertex = std::uint32_t(tables_.positions.size());
    own.first_normal = gpu::kNoIndex;
    tables_.positions.insert(tables_.positions.end(), positions.begin(), positions.end());
    live_vertices_ += positions.size();
    stats_.vertices_written += positions.size();
    const Aabb b = bounds_of(positions.data(), positions.size());
    own.bounds_min = b.min;
    own.bounds_max = b.max;
    tables_.meshes[inst.mesh] = own;
    write_deformed_normals(tables_.meshes[inst.mesh], mesh);
    // Smooth whenever its mesh record has normals: they may come and go as it deforms.
    inst.flags = gpu::kInstanceDeforming | gpu::kInstanceSmooth;
    deforming_.push_back(slot);
  } else {
    inst.mesh = s.shared_mesh;
    if (tables_.meshes[inst.mesh].first_normal != gpu::kNoIndex) inst.flags = gpu::kInstanceSmooth;
  }
  write_transform(registry, slot, wt.world_from_object);
  delta_.instances_added.push_back(slot);
  ++stats_.instances_added;
}

void SceneLayer::remove_instance(std::uint32_t slot) {
  Slot& s = slots_[slot];
  gpu::GpuInstance& inst = tables_.instances[slot];
  if ((inst.flags & gpu::kInstanceStatic) != 0) {
    delta_.static_rebuilt = true; // its baked range goes with the relayout
    tables_.meshes[inst.mesh] = gpu::GpuMesh{};
    tables_.meshes[inst.mesh].first_vertex = gpu::kNoIndex;
    free_meshes_.push_back(inst.mesh); // never in a delta's mesh lists: reusable at once
  } else {
    if (s.deforming) {
      live_vertices_ -= tables_.meshes[inst.mesh].vertex_count;
      tables_.meshes[inst.mesh] = gpu::GpuMesh{};
      tables_.meshes[inst.mesh].first_vertex = gpu::kNoIndex;
      free_meshes_.push_back(inst.mesh);
      deforming_.erase(std::find(deforming_.begin(), deforming_.end(), slot));
    }
    release_shared_mesh(s.source);
    delta_.instances_removed.push_back(slot);
    ++stats_.instances_removed;
  }
  inst = gpu::GpuInstance{};
  inst.mesh = gpu::kNoIndex;
  slot_of_entity_.erase(s.entity.index);
  s = Slot{};
  free_slots_.push_back(slot);
}

void SceneLayer::relayout(ecs::Registry& registry, bool rebake) {
  std::vector<vec3> positions, normals;
  std::vector<uvec3> triangles;
  positions.reserve(live_vertices_);

  // 1. The static set, in entity order, baked into world space (or copied when only compacting).
  std::vector<std::uint32_t> statics;
  for (const auto& [index, slot] : slot_of_entity_)
    if ((tables_.instances[slot].flags & gpu::kInstanceStatic) != 0) statics.push_back(slot);
  std::sort(statics.begin(), statics.end(), [&](std::uint32_t a, std::uint32_t b) {
    return slots_[a].entity.index < slots_[b].entity.index;
  });
  for (const std::uint32_t slot : statics) {
    gpu::GpuInstance& inst = tables_.instances[slot];
    gpu::GpuMesh& record = tables_.meshes[inst.mesh];
    gpu::GpuMesh baked{};
    baked.first_vertex = std::uint32_t(positions.size());
    baked.first_triangle = std::uint32_t(triangles.size());
    baked.first_normal = gpu::kNoIndex;
    if (rebake) {
      const Mesh& mesh = registry.get<Mesh>(slots_[slot].entity);
      const WorldTransform& wt = registry.get<WorldTransform>(slots_[slot].entity);
      slots_[slot].moved_tick = wt.moved_tick;
      const TriangleMesh& m = *mesh.geometry;
      // The world extent checked in double; the vertices placed in float by the render-space
      // matrix, whose translation is small (relative to the render origin, taken in double), so
      // they are as precise as at the world origin — and bit-identical to a world-space float
      // bake there.
      check_extent(registry, slots_[slot].entity,
                   DAabb::transformed(m.bounds(), wt.world_from_object));
      const mat4 render_from_object = render_from(wt.world_from_object);
      for (const vec3& p : m.positions)
        positions.push_back(vec3(render_from_object * vec4(p, 1.0f)));
      if (m.normals.size() == m.positions.size()) {
        baked.first_normal = std::uint32_t(normals.size());
        const mat3 n_from_o = glm::transpose(glm::inverse(mat3(render_from_object)));
        for (const vec3& n : m.normals) normals.push_back(glm::normalize(n_from_o * n));
      }
      triangles.insert(triangles.end(), m.triangles.begin(), m.triangles.end());
      baked.vertex_count = std::uint32_t(m.positions.size());
      baked.triangle_count = std::uint32_t(m.triangles.size());
      stats_.vertices_written += m.positions.size();
    } else {
      const auto first = tables_.positions.begin() + record.first_vertex;
      positions.insert(positions.end(), first, first + record.vertex_count);
      if (record.first_normal != gpu::kNoIndex) {
        baked.first_normal = std::uint32_t(normals.size());
        const auto n = tables_.normals.begin() + record.first_normal;
        normals.insert(normals.end(), n, n + record.vertex_count);
      }
      const auto t = tables_.triangles.begin() + record.first_triangle;
      triangles.insert(triangles.end(), t, t + record.triangle_count);
      baked.vertex_count = record.vertex_count;
      baked.triangle_count = record.triangle_count;
    }
    const Aabb b = bounds_of(positions.data() + baked.first_vertex, baked.vertex_count);
    baked.bounds_min = b.min;
    baked.bounds_max = b.max;
    record = baked;
    inst.world_bounds_min = b.min;
    inst.world_bounds_max = b.max;
  }
  tables_.static_instances = std::move(statics);
  tables_.static_triangle_count = std::uint32_t(triangles.size());

  // 2. Shared object-space meshes, in record order (a layout independent of pointer values).
  std::vector<SharedMesh*> shared;
  for (auto& [source, mesh] : shared_) shared.push_back(&mesh);
  std::sort(shared.begin(), shared.end(),
            [](const SharedMesh* a, const SharedMesh* b) { return a->record < b->record; });
  for (SharedMesh* sm : shared) {
    gpu::GpuMesh& record = tables_.meshes[sm->record];
    const TriangleMesh& m = *sm->source;
    record.first_vertex = std::uint32_t(positions.size());
    record.first_triangle = std::uint32_t(triangles.size());
    positions.insert(positions.end(), m.positions.begin(), m.positions.end());
    triangles.insert(triangles.end(), m.triangles.begin(), m.triangles.end());
    if (record.first_normal != gpu::kNoIndex) {
      record.first_normal = std::uint32_t(normals.size());
      normals.insert(normals.end(), m.normals.begin(), m.normals.end());
    }
  }

  // 3. Deforming instances' own vertices (their triangles are their shared mesh's).
  for (const std::uint32_t slot : deforming_) {
    gpu::GpuMesh& record = tables_.meshes[tables_.instances[slot].mesh];
    const auto first = tables_.positions.begin() + record.first_vertex;
    const std::uint32_t first_vertex = std::uint32_t(positions.size());
    positions.insert(positions.end(), first, first + record.vertex_count);
    record.first_vertex = first_vertex;
    record.first_triangle = tables_.meshes[slots_[slot].shared_mesh].first_triangle;
    if (record.first_normal != gpu::kNoIndex) {
      const auto n = tables_.normals.begin() + record.first_normal;
      record.first_normal = std::uint32_t(normals.size());
      normals.insert(normals.end(), n, n + record.vertex_count);
    }
  }

  tables_.positions = std::move(positions);
  tables_.normals = std::move(normals);
  tables_.triangles = std::move(triangles);
  live_vertices_ = tables_.positions.size();
  dropped_normals_ = 0;
  delta_.geometry_relocated = true;
  ++stats_.relayouts;
  if (rebake) {
    ++stats_.static_bakes;
    delta_.static_rebuilt = true;
  }
}

} // namespace specula
