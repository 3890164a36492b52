#pragma once
/// \file
/// The native backend: Specula's own structures behind the Tracer interface, after the real-time
/// CPU ray tracer of Bui Phu & Le — two levels, split by kinematics:
///   - the static set (baked in world space by the scene layer) in one structure built once: the
///     SAH kd-tree by default (engine/accel/kdtree), or a BVH or a uniform grid (options);
///   - each object-space mesh that rigid dynamic instances share gets one BVH, built when the
///     first instance needs it (lazily expanded subtrees as an option); moving an instance only
///     rewrites its transform;
///   - a deforming instance owns its BVH: refitted when the layer reports its vertices rewritten,
///     and its degraded subtrees rebuilt (selective restructuring) when their SAH cost has grown
///     past a threshold;
///   - a top-level BVH over the dynamic instances' world bounds, rebuilt in any frame in which one
///     of them changed (hierarchical objects move every frame: a few hundred boxes at most).
/// Rays enter an instance through its object_from_world transform (directions not renormalised,
/// so distances stay comparable across levels). Only the layer's delta causes work;
/// last_update() counts and times what was done.

#include "specula/accel/bvh/bvh.h"
#include "specula/accel/bvh/wide_bvh.h"
#include "specula/accel/common/ray_query.h"
#include "specula/accel/grid/grid.h"
#include "specula/accel/kdtree/kdtree.h"
#include "specula/trace/tracer.h"

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <unordered_map>
#include <vector>

namespace specula {

struct SceneTables;

/// The structure that holds the static set.
enum class StaticStructure : std::uint8_t { kdtree, bvh, grid };

struct NativeOptions {
  StaticStructure static_structure = StaticStructure::kdtree;
  accel::TriangleTest triangle_test = accel::TriangleTest::watertight;
  /// Per-mesh BVHs expand their deeper subtrees on first visit.
  bool lazy_blas = false;
  /// A deforming mesh's subtree is rebuilt once its SAH cost exceeds this multiple of its cost
  /// when last built.
  float restructure_threshold = 1.3f;
  /// Target cells per static triangle when the static set is a grid (accel::GridBuildOptions).
  float grid_density = accel::GridBuildOptions{}.density;
  /// Single rays traverse the 4-wide collapse (accel::WideBvh) of the static set's BVH (when
  /// the static set is a BVH; its camera packets too) and of each shared mesh's BVH (rigid
  /// instances; not a lazy one, which would have to be expanded whole). Deforming meshes' BVHs,
  /// refitted every frame, keep the binary trees. Off: single rays use the binary trees too, as the
  /// Vulkan device does — the CPU mirror of the device, hit for hit (at a shared edge, two
  /// triangles at the same t, the wide tree may report the other one).
  bool wide_bvh = true;
};

class NativeTracer final : public Tracer {
public:
  explicit NativeTracer(std::uint32_t packet_width = 8, NativeOptions options = {});
  ~NativeTracer() override;
  NativeTracer(const NativeTracer&) = delete;
  NativeTracer& operator=(const NativeTracer&) = delete;

  /// "native" (kd-tree), "native-bvh" or "native-grid": the backend name that selects these
  /// options.
  [[nodiscard]] std::string_view name() const override { return name_; }
  const TracerUpdateStats& update(const SceneLayer& layer) override;
  [[nodiscard]] const TracerUpdateStats& last_update() const override { return last_; }
  void intersect(std::span<const Ray> rays, std::span<Hit> hits) const override;
  void occluded(std::span<const Ray> rays, std::span<std::uint8_t> occluded) const override;
  void intersect_camera(const CameraRays& camera, const PacketTile& tile,
                        PrimaryHits& hits) const override;
  [[nodiscard]] std::uint32_t packet_width() const override { return packet_width_; }
  void set_packet_width(std::uint32_t width) override;

  [[nodiscard]] const NativeOptions& options() const { return options_; }
  [[nodiscard]] const accel::KdTree& kdtree() const { return kd_; }
  [[nodiscard]] const accel::Bvh& static_bvh() const { return static_bvh_; }
  [[nodiscard]] const accel::UniformGrid& grid() const { return grid_; }

  // What the Vulkan path flattens onto the device (engine/gpu/gpu_scene.cpp), read-only.
  /// The static set as its structure indexes it: triangle i belongs to instance static_slots()[k]
  /// for the last k with static_first_triangles()[k] <= i (its triangle i - that within the mesh).
  [[nodiscard]] std::span<const std::uint32_t> static_first_triangles() const {
    return static_first_triangle_;
  }
  [[nodiscard]] std::span<const std::uint32_t> static_slots() const { return static_slot_; }
  [[nodiscard]] bool has_static() const { return has_static_; }
  /// The top level over dynamic instances' world bounds; box i holds top_entry(i).
  [[nodiscard]] const accel::Bvh& top_level() const { return top_; }
  struct TopEntry {
    std::uint32_t slot;      ///< instance slot
    const accel::Bvh* blas;  ///< over the triangles of the instance's mesh (shared or its own)
    mat4 object_from_world;  ///< as the CPU traversal uses it (inverted in double)
    bool identity;
  };
  [[nodiscard]] std::size_t top_entry_count() const { return top_slot_.size(); }
  [[nodiscard]] TopEntry top_entry(std::size_t box) const {
    const Dynamic& d = *top_entry_[box];
    return {top_slot_[box], &d.blas->bvh, d.object_from_world, d.identity};
  }

private:
  /// A mesh's own copy of its geometry (object space) and its BVH; addresses stay put.
  struct Blas {
    std::vector<vec3> positions;
    std::vector<uvec3> triangles;
    accel::Bvh bvh;
    accel::WideBvh wide; ///< single rays, when not empty (rigid meshes with options_.wide_bvh)
    [[nodiscard]] accel::TriangleView view() const {
      return {positions.data(), triangles.data(), std::uint32_t(triangles.size())};
    }
  };
  struct Dynamic {
    const Blas* blas = nullptr;
    std::unique_ptr<Blas> own; ///< deforming instances only
    mat4 world_from_object{1.0f};
    mat4 object_from_world{1.0f}; ///< inverted in double (identity when not traceable)
    bool identity = false;
    bool traceable = true; ///< accel::traceable_instance: false keeps it out of the top level
  };

  template <accel::TriangleTest Test>
  void intersect_one(accel::PreparedRay& r, Hit& hit) const;
  template <accel::TriangleTest Test>
  [[nodiscard]] bool occluded_one(const accel::PreparedRay& r) const;
  /// Whether a dynamic instance blocks r.
  template <accel::TriangleTest Test>
  [[nodiscard]] bool occluded_dynamic(const accel::PreparedRay& r) const;
  /// intersect() over the static kd-tree: consecutive rays as packets of N.
  template <int N>
  void intersect_packets(std::span<const Ray> rays, std::span<Hit> hits) const;
  /// occluded() over the static kd-tree or 4-wide BVH: consecutive rays as packets of N.
  template <int N>
  void occluded_packets(std::span<const Ray> rays, std::span<std::uint8_t> occluded) const;
  /// Closest hit among the dynamic instances, closer than r.tfar (which it shrinks).
  template <accel::TriangleTest Test>
  void intersect_dynamic(accel::PreparedRay& r, Hit& hit) const;
  template <int N>
  void intersect_camera_packets(const PacketTile& tile, PrimaryHits& hits, const vec3& origin) const;
  void resolve_static(const accel::TriangleHit& th, Hit& hit) const;

  void rebuild_static(const SceneTables& tables);
  static void copy_mesh(const SceneTables& tables, std::uint32_t mesh, Blas& out);
  const Blas* shared_blas(const SceneTables& tables, std::uint32_t mesh);
  void set_transform(Dynamic& d, const mat4& world_from_object);
  void rebuild_top();

  std::uint32_t packet_width_;
  NativeOptions options_;
  std::string name_;
  // Static set: world-space copy with absolute vertex indices.
  std::vector<vec3> static_positions_;
  std::vector<uvec3> static_triangles_;
  std::vector<std::uint32_t> static_first_triangle_; ///< per static instance, ascending
  std::vector<std::uint32_t> static_slot_;           ///< the instance slot of each
  accel::KdTree kd_;
  accel::Bvh static_bvh_;
  accel::WideBvh static_wide_; ///< empty unless options_.wide_bvh
  accel::UniformGrid grid_;
  bool has_static_ = false;
  // Dynamic instances.
  std::unordered_map<std::uint32_t, std::unique_ptr<Blas>> blas_; ///< by shared mesh record
  std::unordered_map<std::uint32_t, Dynamic> dynamic_;            ///< by instance slot
  std::uint64_t synced_ = 0; ///< the layer's sync this tracer applied last (SceneLayer::syncs)
  accel::Bvh top_;
  std::vector<std::uint32_t> top_slot_;    ///< instance slot of each top-level box
  std::vector<const Dynamic*> top_entry_;  ///< and its record
  TracerUpdateStats last_;
};

} // namespace specula
