#pragma once
/// \file
/// The Embree part of the acceleration structures: two levels, as the real-time ray tracer paper
/// (Bui Phu & Le, after Wald) separates static from dynamic geometry.
///   - Static entities (Kinematics::Static, not animated) are baked into world space in one
///     Embree scene built once with RTC_BUILD_QUALITY_HIGH.
///   - Each hierarchical or free entity is an instance of a per-mesh scene (BLAS), shared by all
///     entities with the same TriangleMesh; moving it only rewrites its instance transform.
///   - A deforming entity (vertex animation) owns its BLAS, built with RTC_BUILD_QUALITY_REFIT and
///     refitted when its positions change.
///   - The top-level scene holds the static scene's instance and the dynamic instances; it is
///     recommitted only when one of them changed.
/// Only entities that changed cause work; last_update() counts what was done.

#include "specula/ecs/registry.h"
#include "specula/geometry/ray.h"
#include "specula/trace/surface.h"

#include <embree3/rtcore.h>

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <span>
#include <unordered_map>
#include <vector>

namespace specula {

/// Work done by one EmbreeAccel::update.
struct AccelUpdateStats {
  std::uint32_t static_builds = 0;     ///< static scene (re)built
  std::uint32_t blas_builds = 0;       ///< per-mesh scenes built
  std::uint32_t blas_refits = 0;       ///< deforming meshes refitted
  std::uint32_t instances_added = 0;
  std::uint32_t instances_removed = 0;
  std::uint32_t instances_moved = 0;   ///< instance transforms rewritten
  bool top_committed = false;          ///< the top-level scene was recommitted
  std::uint32_t static_triangles = 0;  ///< triangles in the static scene
  std::uint32_t dynamic_instances = 0; ///< instances in the top-level scene (static one excluded)
};

class EmbreeAccel {
public:
  EmbreeAccel();
  ~EmbreeAccel();
  EmbreeAccel(const EmbreeAccel&) = delete;
  EmbreeAccel& operator=(const EmbreeAccel&) = delete;

  /// Brings the structures up to date with the registry's Mesh, Kinematics, Animation,
  /// WorldTransform and Material components (world transforms must be current). Throws
  /// specula::Error when Embree reports a failure.
  AccelUpdateStats update(ecs::Registry& registry);
  [[nodiscard]] const AccelUpdateStats& last_update() const { return last_; }

  /// The surface table hits index into (valid until the next update).
  [[nodiscard]] std::span<const Surface> surfaces() const { return surfaces_; }
  [[nodiscard]] RTCScene scene() const { return top_; }
  [[nodiscard]] RTCDevice device() const { return device_; }

  /// Fills `hit` from an Embree ray-hit record (surface index, object-space normal, barycentrics).
  void resolve(unsigned geom_id, unsigned inst_id, float ng_x, float ng_y, float ng_z, float u,
               float v, float t, unsigned prim_id, Hit& hit) const {
    if (geom_id == RTC_INVALID_GEOMETRY_ID) {
      hit = Hit{};
      return;
    }
    const std::uint32_t surface = inst_id == static_instance_id_ ? static_surface_of_geom_[geom_id]
                                                                 : surface_of_instance_[inst_id];
    hit.t = t;
    hit.surface = surface;
    hit.primitive = prim_id;
    hit.uv = vec2(u, v);
    hit.object_normal = vec3(ng_x, ng_y, ng_z);
  }

private:
  struct Blas {
    RTCScene scene = nullptr;
    std::uint32_t users = 0;
  };
  struct Dynamic {
    ecs::Entity entity;
    RTCGeometry instance = nullptr;
    unsigned instance_id = RTC_INVALID_GEOMETRY_ID;
    const TriangleMesh* geometry = nullptr;
    RTCScene own_blas = nullptr;   ///< deforming meshes only
    RTCGeometry own_mesh = nullptr;
    std::uint64_t deformed_tick = 0;
    mat4 world_from_object{0.0f};
    bool seen = false;
  };
  struct StaticEntry {
    ecs::Entity entity;
    const TriangleMesh* geometry;
    mat4 world_from_object;
    friend bool operator==(const StaticEntry&, const StaticEntry&) = default;
  };

  void rebuild_static(ecs::Registry& registry, const std::vector<StaticEntry>& entries);
  RTCScene shared_blas(const std::shared_ptr<const TriangleMesh>& mesh);
  void release_dynamic(Dynamic& d);
  void check(const char* what);
  static void on_error(void* user, RTCError code, const char* message);

  RTCDevice device_ = nullptr;
  RTCScene top_ = nullptr;
  RTCScene static_scene_ = nullptr;
  RTCGeometry static_instance_ = nullptr;
  unsigned static_instance_id_ = RTC_INVALID_GEOMETRY_ID;
  std::vector<StaticEntry> static_entries_;
  std::vector<std::unique_ptr<TriangleMesh>> baked_;      ///< static meshes in world space
  std::vector<std::uint32_t> static_surface_of_geom_;
  std::unordered_map<const TriangleMesh*, Blas> blas_;
  std::unordered_map<std::uint32_t, Dynamic> dynamic_;    ///< by entity slot index
  std::vector<std::uint32_t> surface_of_instance_;        ///< by top-level geometry id
  std::vector<Surface> surfaces_;
  std::vector<std::shared_ptr<const TriangleMesh>> keep_alive_;
  AccelUpdateStats last_;
  std::mutex error_mutex_;
  std::string last_error_; ///< the latest message Embree reported, consumed by check()
};

} // namespace specula
