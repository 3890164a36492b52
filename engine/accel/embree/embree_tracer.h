#pragma once
/// \file
/// The Embree backend: Embree's structures built from the scene layer's tables, and the batch
/// queries the integrators ask for. Two levels, as the real-time ray tracer paper (Bui Phu & Le,
/// after Wald) separates static from dynamic geometry:
///   - the static set, already baked in world space by the layer, is one Embree scene built with
///     RTC_BUILD_QUALITY_HIGH, rebuilt only when the layer says the static set changed;
///   - each object-space mesh the layer shares between dynamic instances gets one scene (BLAS);
///     moving an instance only rewrites its transform;
///   - a deforming instance owns a BLAS built with RTC_BUILD_QUALITY_REFIT and refitted when the
///     layer reports its vertices rewritten; Embree does not expose its tree, so a binned-SAH
///     BVH of Specula's own over the same triangles (refitted alike, never traced) stands in for
///     it: when that tree's SAH cost has grown past `restructure_threshold` of its cost when
///     built, the topology has degraded (triangles scattered away from their build neighbours)
///     and the BLAS is rebuilt from scratch, with its stand-in (selective restructuring, whole
///     meshes: Embree rebuilds no subtree alone);
///   - the top level holds the static scene (geometry id 0) and one instance per dynamic instance
///     slot s (geometry id s + 1), and is recommitted only when one of them changed.
/// Only the layer's delta causes work; last_update() counts what was done.

#include "specula/trace/tracer.h"

#include <embree3/rtcore.h>

#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

namespace specula {

struct SceneTables;

class EmbreeTracer final : public Tracer {
public:
  /// packet_width: 1, 4, 8 or 16. Throws specula::Error when Embree cannot create a device.
  /// restructure_threshold: a deforming mesh's BLAS is rebuilt once its stand-in tree's SAH cost
  /// exceeds this times its cost when built (the native backend's default; +inf: never).
  explicit EmbreeTracer(std::uint32_t packet_width = 16, float restructure_threshold = 1.3f);
  ~EmbreeTracer() override;
  EmbreeTracer(const EmbreeTracer&) = delete;
  EmbreeTracer& operator=(const EmbreeTracer&) = delete;

  [[nodiscard]] std::string_view name() const override { return "embree"; }
  const TracerUpdateStats& update(const SceneLayer& layer) override;
  [[nodiscard]] const TracerUpdateStats& last_update() const override { return last_; }
  void intersect(std::span<const Ray> rays, std::span<Hit> hits) const override;
  void occluded(std::span<const Ray> rays, std::span<std::uint8_t> occluded) const override;
  /// Packets of 16 rays (rtcOccluded16, coherent context) against the static scene when it is the
  /// whole scene (no dynamic instance in the top level); occluded() otherwise. Embree 3.13.5's
  /// packet occlusion through an instance, the top level's static instance included, can loop
  /// forever on an ordinary ray (a Cornell-box shadow ray; rtcOccluded1M with the coherent flag
  /// takes the same path), so packets never go through the top level.
  void occluded_coherent(std::span<const Ray> rays,
                         std::span<std::uint8_t> occluded) const override;
  void intersect_camera(const CameraRays& camera, const PacketTile& tile,
                        PrimaryHits& hits) const override;
  [[nodiscard]] std::uint32_t packet_width() const override { return packet_width_; }
  void set_packet_width(std::uint32_t width) override;

  /// The top-level scene (for benchmarks that call Embree directly on the same structure).
  [[nodiscard]] RTCScene scene() const { return top_; }

private:
  struct DegradationProbe; // embree_tracer.cpp
  struct Dynamic {
    RTCGeometry instance = nullptr;
    RTCScene blas = nullptr;     ///< the scene it instances (shared or own_blas)
    bool attached = false;       ///< in the top level (false: degenerate, hidden)
    RTCScene own_blas = nullptr; ///< deforming instances only
    RTCGeometry own_mesh = nullptr;
    std::uint32_t triangles = 0; ///< in its mesh (the update stats' triangle counts)
    /// Deforming instances: the stand-in tree whose SAH cost tells when to rebuild own_blas.
    std::shared_ptr<DegradationProbe> probe;
  };

  /// Builds instance `slot`'s own BLAS (a deforming mesh) and its degradation probe into `d`,
  /// replacing any it had.
  void build_deforming(const SceneTables& tables, std::uint32_t slot, Dynamic& d);

  /// The scene single rays are traced in: the static scene when it is the whole scene, else the
  /// top level.
  [[nodiscard]] RTCScene ray_scene() const;
  /// The instance slot of an Embree hit (instance id 0: the static scene, by geometry id).
  [[nodiscard]] std::uint32_t slot_of(unsigned geom_id, unsigned inst_id) const {
    return inst_id == 0 ? static_slot_of_geom_[geom_id] : inst_id - 1;
  }
  template <int N, typename RayHitN, typename IntersectN>
  void intersect_camera_packets(const PacketTile& tile, PrimaryHits& hits, const vec3& origin,
                                IntersectN intersect_n) const;
  void rebuild_static(const SceneTables& tables);
  RTCScene shared_blas(const SceneTables& tables, std::uint32_t mesh);
  void release_dynamic(std::uint32_t slot);
  /// Gives the instance its transform and puts it in the top level, or takes it out when the
  /// transform or its bounds are degenerate (accel::traceable_instance).
  void place(std::uint32_t slot, Dynamic& d, const mat4& world_from_object);
  RTCGeometry make_triangles(const SceneTables& tables, std::uint32_t mesh,
                             RTCBuildQuality quality);
  void check(const char* what);
  static void on_error(void* user, RTCError code, const char* message);

  std::uint32_t packet_width_;
  float restructure_threshold_;
  RTCDevice device_ = nullptr;
  RTCScene top_ = nullptr;
  RTCScene static_scene_ = nullptr;
  RTCGeometry static_instance_ = nullptr;
  std::vector<std::uint32_t> static_slot_of_geom_;
  std::unordered_map<std::uint32_t, RTCScene> blas_;   ///< by shared mesh record
  std::unordered_map<std::uint32_t, Dynamic> dynamic_; ///< by instance slot
  std::uint64_t synced_ = 0; ///< the layer's sync this tracer applied last (SceneLayer::syncs)
  TracerUpdateStats last_;
  std::uint32_t static_triangles_ = 0;
  std::mutex error_mutex_;
  std::string last_error_; ///< the latest message Embree reported, consumed by check()
};

} // namespace specula
