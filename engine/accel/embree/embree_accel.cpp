#include "specula/accel/embree/embree_accel.h"

#include "specula/core/error.h"
#include "specula/core/log.h"
#include "specula/scene/components/animation.h"
#include "specula/scene/components/kinematics.h"
#include "specula/scene/components/material.h"
#include "specula/scene/components/mesh.h"
#include "specula/scene/components/world_transform.h"

#include <algorithm>
#include <cstring>
#include <string>

namespace specula {
namespace {


mat3 normal_matrix(const mat4& world_from_object) {
  return glm::transpose(glm::inverse(mat3(world_from_object)));
}

/// An Embree triangle geometry holding copies of `positions` and `mesh`'s triangles.
RTCGeometry make_triangles(RTCDevice device, const std::vector<vec3>& positions,
                           const TriangleMesh& mesh, RTCBuildQuality quality) {
  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
      geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), positions.size()));
  auto* indices = static_cast<std::uint32_t*>(rtcSetNewGeometryBuffer(
      geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(std::uint32_t),
      mesh.triangles.size()));
  if (vertices == nullptr || indices == nullptr) {
    rtcReleaseGeometry(geom);
    return nullptr;
  }
  std::memcpy(vertices, positions.data(), positions.size() * sizeof(vec3));
  std::memcpy(indices, mesh.triangles.data(), mesh.triangles.size() * sizeof(uvec3));
  rtcSetGeometryBuildQuality(geom, quality);
  rtcCommitGeometry(geom);
  return geom;
}

bool is_dynamic(ecs::Registry& registry, ecs::Entity e, const Mesh& mesh) {
  const Kinematics* k = registry.try_get<Kinematics>(e);
  return (k != nullptr && k->type != Kinematics::Type::Static) || registry.has<Animation>(e) ||
         !mesh.deformed_positions.empty();
}

} // namespace

static_assert(sizeof(vec3) == 3 * sizeof(float) && sizeof(uvec3) == 3 * sizeof(std::uint32_t),
              "Embree buffers are filled with memcpy from GLM vectors");

void EmbreeAccel::on_error(void* user, RTCError code, const char* message) {
  // Embree may call this from its own build threads: keep the text under a lock for check().
  auto* self = static_cast<EmbreeAccel*>(user);
  const std::lock_guard lock(self->error_mutex_);
  self->last_error_ = "Embree error " + std::to_string(int(code)) + ": " + (message ? message : "");
}

EmbreeAccel::EmbreeAccel() {
  device_ = rtcNewDevice("verbose=0");
  if (device_ == nullptr) throw Error("embree", "cannot create an Embree device");
  rtcSetDeviceErrorFunction(device_, &EmbreeAccel::on_error, this);
  top_ = rtcNewScene(device_);
  rtcSetSceneFlags(top_, RTC_SCENE_FLAG_DYNAMIC | RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(top_, RTC_BUILD_QUALITY_LOW);
  rtcCommitScene(top_);
  check("creating the top-level scene");
}

EmbreeAccel::~EmbreeAccel() {
  for (auto& [index, d] : dynamic_) release_dynamic(d);
  for (auto& [mesh, blas] : blas_) rtcReleaseScene(blas.scene);
  if (static_instance_) rtcReleaseGeometry(static_instance_);
  if (static_scene_) rtcReleaseScene(static_scene_);
  if (top_) rtcReleaseScene(top_);
  if (device_) rtcReleaseDevice(device_);
}

void EmbreeAccel::check(const char* what) {
  const RTCError code = rtcGetDeviceError(device_);
  if (code == RTC_ERROR_NONE) return;
  std::string message;
  {
    const std::lock_guard lock(error_mutex_);
    message.swap(last_error_);
  }
  if (message.empty()) message = "Embree error " + std::to_string(int(code));
  throw Error("embree", std::string(what) + ": " + message);
}

RTCScene EmbreeAccel::shared_blas(const std::shared_ptr<const TriangleMesh>& mesh) {
  Blas& blas = blas_[mesh.get()];
  if (blas.scene == nullptr) {
    blas.scene = rtcNewScene(device_);
    rtcSetSceneFlags(blas.scene, RTC_SCENE_FLAG_ROBUST);
    rtcSetSceneBuildQuality(blas.scene, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry geom = make_triangles(device_, mesh->positions, *mesh, RTC_BUILD_QUALITY_HIGH);
    if (geom == nullptr) check("allocating a mesh");
    rtcAttachGeometry(blas.scene, geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(blas.scene);
    check("building a mesh's structure");
    keep_alive_.push_back(mesh);
    ++last_.blas_builds;
  }
  ++blas.users;
  return blas.scene;
}

void EmbreeAccel::release_dynamic(Dynamic& d) {
  if (d.instance != nullptr) {
    rtcDetachGeometry(top_, d.instance_id);
    rtcReleaseGeometry(d.instance);
    d.instance = nullptr;
  }
  if (d.own_blas != nullptr) {
    rtcReleaseScene(d.own_blas);
    d.own_blas = nullptr;
    d.own_mesh = nullptr; // owned by the scene
  } else if (auto it = blas_.find(d.geometry); it != blas_.end() && it->second.users > 0) {
    // Shared structures stay cached for the life of the accel: an entity that comes back, or
    // another entity with the same mesh, reuses them.
    --it->second.users;
  }
}

void EmbreeAccel::rebuild_static(ecs::Registry& registry, const std::vector<StaticEntry>& entries) {
  if (static_instance_ != nullptr) {
    rtcDetachGeometry(top_, static_instance_id_);
    rtcReleaseGeometry(static_instance_);
    static_instance_ = nullptr;
    static_instance_id_ = RTC_INVALID_GEOMETRY_ID;
  }
  if (static_scene_ != nullptr) rtcReleaseScene(static_scene_);
  static_scene_ = nullptr;
  baked_.clear();
  static_entries_ = entries;
  last_.static_triangles = 0;
  if (entries.empty()) return;

  static_scene_ = rtcNewScene(device_);
  rtcSetSceneFlags(static_scene_, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(static_scene_, RTC_BUILD_QUALITY_HIGH);
  for (const StaticEntry& entry : entries) {
    const Mesh& mesh = registry.get<Mesh>(entry.entity);
    // Bake into world space: one structure for every static triangle, no per-ray transform.
    auto baked = std::make_unique<TriangleMesh>();
    baked->triangles = mesh.geometry->triangles;
    baked->positions.reserve(mesh.geometry->positions.size());
    for (const vec3& p : mesh.geometry->positions)
      baked->positions.push_back(vec3(entry.world_from_object * vec4(p, 1.0f)));
    const mat3 n_from_o = normal_matrix(entry.world_from_object);
    baked->normals.reserve(mesh.geometry->normals.size());
    for (const vec3& n : mesh.geometry->normals) baked->normals.push_back(glm::normalize(n_from_o * n));
    RTCGeometry geom = make_triangles(device_, baked->positions, *baked, RTC_BUILD_QUALITY_HIGH);
    if (geom == nullptr) check("allocating the static scene");
    rtcAttachGeometry(static_scene_, geom);
    rtcReleaseGeometry(geom);
    last_.static_triangles += std::uint32_t(baked->triangles.size());
    baked_.push_back(std::move(baked));
  }
  rtcCommitScene(static_scene_);
  check("building the static scene");
  static_instance_ = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_INSTANCE);
  rtcSetGeometryInstancedScene(static_instance_, static_scene_);
  const mat4 identity(1.0f);
  rtcSetGeometryTransform(static_instance_, 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR, &identity[0][0]);
  rtcCommitGeometry(static_instance_);
  static_instance_id_ = rtcAttachGeometry(top_, static_instance_);
  ++last_.static_builds;
}

AccelUpdateStats EmbreeAccel::update(ecs::Registry& registry) {
  last_ = AccelUpdateStats{};
  bool top_dirty = false;

  // --- Static set: rebuilt only when its membership, meshes or placement changed. ---
  std::vector<StaticEntry> statics;
  registry.view<Mesh, WorldTransform>().each([&](ecs::Entity e, const Mesh& mesh, const WorldTransform& wt) {
    if (mesh.geometry && !is_dynamic(registry, e, mesh))
      statics.push_back({e, mesh.geometry.get(), wt.world_from_object});
  });
  std::sort(statics.begin(), statics.end(),
            [](const StaticEntry& a, const StaticEntry& b) { return a.entity.index < b.entity.index; });
  if (statics != static_entries_) {
    if (!static_entries_.empty())
      log_warning("static geometry changed after load: rebuilding the static structure (mark "
                  "moving entities 'hierarchical' or 'free')");
    rebuild_static(registry, statics);
    top_dirty = true;
  }
  last_.static_triangles = 0;
  for (const auto& baked : baked_) last_.static_triangles += std::uint32_t(baked->triangles.size());

  // --- Dynamic instances: add new ones, move moved ones, refit deformed ones. ---
  for (auto& [index, d] : dynamic_) d.seen = false;
  registry.view<Mesh, WorldTransform>().each([&](ecs::Entity e, const Mesh& mesh, const WorldTransform& wt) {
    if (!mesh.geometry || !is_dynamic(registry, e, mesh)) return;
    auto [it, inserted] = dynamic_.try_emplace(e.index);
    Dynamic& d = it->second;
    const bool deforming = !mesh.deformed_positions.empty();
    if (!inserted && (d.entity != e || d.geometry != mesh.geometry.get() ||
                      (d.own_blas != nullptr) != deforming)) {
      // The slot was recycled for another entity, or the mesh was swapped: start over.
      release_dynamic(d);
      ++last_.instances_removed;
      d = Dynamic{};
      inserted = true;
    }
    d.seen = true;
    if (inserted) {
      d.entity = e;
      d.geometry = mesh.geometry.get();
      RTCScene blas = nullptr;
      if (deforming) {
        d.own_blas = rtcNewScene(device_);
        rtcSetSceneFlags(d.own_blas, RTC_SCENE_FLAG_DYNAMIC | RTC_SCENE_FLAG_ROBUST);
        d.own_mesh = make_triangles(device_, mesh.deformed_positions, *mesh.geometry,
                                    RTC_BUILD_QUALITY_REFIT);
        if (d.own_mesh == nullptr) check("allocating a deforming mesh");
        rtcAttachGeometry(d.own_blas, d.own_mesh);
        rtcReleaseGeometry(d.own_mesh); // the scene keeps it
        rtcCommitScene(d.own_blas);
        check("building a deforming mesh's structure");
        d.deformed_tick = mesh.deformed_tick;
        ++last_.blas_builds;
        blas = d.own_blas;
      } else {
        blas = shared_blas(mesh.geometry);
      }
      d.instance = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_INSTANCE);
      rtcSetGeometryInstancedScene(d.instance, blas);
      rtcSetGeometryTransform(d.instance, 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR, &wt.world_from_object[0][0]);
      rtcCommitGeometry(d.instance);
      d.instance_id = rtcAttachGeometry(top_, d.instance);
      d.world_from_object = wt.world_from_object;
      ++last_.instances_added;
      top_dirty = true;
      return;
    }
    if (deforming && mesh.deformed_tick != d.deformed_tick) {
      auto* vertices = static_cast<float*>(rtcGetGeometryBufferData(d.own_mesh, RTC_BUFFER_TYPE_VERTEX, 0));
      std::memcpy(vertices, mesh.deformed_positions.data(), mesh.deformed_positions.size() * sizeof(vec3));
      rtcUpdateGeometryBuffer(d.own_mesh, RTC_BUFFER_TYPE_VERTEX, 0);
      rtcCommitGeometry(d.own_mesh);
      rtcCommitScene(d.own_blas); // refit: the topology is unchanged
      check("refitting a deforming mesh");
      d.deformed_tick = mesh.deformed_tick;
      ++last_.blas_refits;
      top_dirty = true; // the instance's bounds changed
    }
    if (wt.world_from_object != d.world_from_object) {
      rtcSetGeometryTransform(d.instance, 0, RTC_FORMAT_FLOAT4X4_COLUMN_MAJOR, &wt.world_from_object[0][0]);
      rtcCommitGeometry(d.instance);
      d.world_from_object = wt.world_from_object;
      ++last_.instances_moved;
      top_dirty = true;
    }
  });
  for (auto it = dynamic_.begin(); it != dynamic_.end();) {
    if (!it->second.seen) {
      release_dynamic(it->second);
      ++last_.instances_removed;
      top_dirty = true;
      it = dynamic_.erase(it);
    } else {
      ++it;
    }
  }

  if (top_dirty) {
    rtcCommitScene(top_);
    check("committing the top-level scene");
    last_.top_committed = true;
  }

  // --- Surface table: materials and normal matrices as of this frame. ---
  surfaces_.clear();
  static_surface_of_geom_.assign(static_entries_.size(), 0);
  for (std::size_t g = 0; g < static_entries_.size(); ++g) {
    const ecs::Entity e = static_entries_[g].entity;
    const Material* m = registry.try_get<Material>(e);
    static_surface_of_geom_[g] = std::uint32_t(surfaces_.size());
    surfaces_.push_back(Surface{e, m ? *m : Material{}, baked_[g].get(), baked_[g]->positions.data(),
                                mat4(1.0f), mat3(1.0f), true});
  }
  surface_of_instance_.clear();
  for (const auto& [index, d] : dynamic_) {
    if (d.instance_id >= surface_of_instance_.size()) surface_of_instance_.resize(d.instance_id + 1, kNoSurface);
    surface_of_instance_[d.instance_id] = std::uint32_t(surfaces_.size());
    const Material* m = registry.try_get<Material>(d.entity);
    const Mesh& mesh = registry.get<Mesh>(d.entity);
    surfaces_.push_back(Surface{d.entity, m ? *m : Material{}, d.geometry, mesh.positions().data(),
                                d.world_from_object, normal_matrix(d.world_from_object),
                                d.own_blas == nullptr});
  }
  last_.dynamic_instances = std::uint32_t(dynamic_.size());
  return last_;
}

} // namespace specula
