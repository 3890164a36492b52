#pragma once
/// \file
/// The scene on the device: the buffers shaders/include/trace.glsl reads at bindings
/// [0, kSceneBindings) of set 0 (shaders/shared/gpu_scene_layout.h), brought up to date from the
/// scene layer's delta.
///
/// The structures are the native backend's (a NativeTracer with the static set in a binned-SAH
/// BVH or a uniform grid owns them: per-mesh BVHs shared by rigid instances, deforming instances'
/// own refitted BVHs, the top level over dynamic instances' world bounds); this class only flattens
/// their arrays into the device layout. Uploads follow the delta: a frame where nothing changed
/// uploads nothing; one where only instances moved uploads their table entries, their top-level
/// entries and the top level; a deformation uploads the instance's vertices and the node array;
/// anything else (a static rebuild, instances or meshes added or removed, relocated pools)
/// uploads everything.

#include "specula/accel/native/native_tracer.h"
#include "specula/gpu/vk_context.h"
#include "specula/shared/gpu_scene_layout.h"
#include "specula/shared/trace_layout.h"
#include "specula/trace/tracer.h"

#include <array>
#include <cstdint>
#include <span>
#include <unordered_map>
#include <vector>

namespace specula {
class SceneLayer;
}

namespace specula::gpu {

/// The structure the static set is traced with on the device (dynamic instances always go
/// through a top-level BVH over per-mesh BVHs).
enum class GpuStructure : std::uint8_t { bvh, grid };

/// What the latest update() wrote to the device.
struct GpuUploadStats {
  std::uint64_t bytes = 0;
  std::uint32_t writes = 0; ///< buffer uploads (whole buffers or ranges)
  bool full = false;        ///< every buffer was rewritten
};

class GpuScene {
public:
  /// `grid_density`: target cells per static triangle (GpuStructure::grid).
  GpuScene(Context& context, GpuStructure structure, float grid_density = 4.0f);
  GpuScene(const GpuScene&) = delete;
  GpuScene& operator=(const GpuScene&) = delete;

  /// Applies the layer's latest delta; the first call uploads everything.
  const TracerUpdateStats& update(const SceneLayer& layer);
  [[nodiscard]] const TracerUpdateStats& last_update() const { return native_.last_update(); }
  [[nodiscard]] const GpuUploadStats& last_upload() const { return upload_; }

  /// The buffers of bindings [0, kSceneBindings), in binding order.
  [[nodiscard]] std::span<const Buffer* const> bindings() const { return bindings_; }
  /// The scene's bindings that trace.glsl reads as texel buffers, for the PipelineDesc of every
  /// kernel that binds the scene: the nodes (binding 5, two RGBA32UI texels each) and the traced
  /// triangles (binding 7, one RGBA32UI texel per vertex).
  [[nodiscard]] static std::vector<TexelBinding> texel_bindings();
  [[nodiscard]] GpuStructure structure() const { return structure_; }
  [[nodiscard]] Context& context() const { return context_; }
  /// Stack entries a ray's walk may need (at most kTraceStackSize).
  [[nodiscard]] std::uint32_t stack_depth() const { return stack_depth_; }
  /// The top level's boxes as uploaded (binding 4 after the header), in box order: each dynamic
  /// instance's slot and object_from_world (hybrid mode maps slots to boxes with them).
  [[nodiscard]] std::span<const GpuTopEntry> top_entries() const { return top_.entries; }
  /// Whether the uploaded scene has dynamic instances (a top level to walk).
  [[nodiscard]] bool has_top_level() const { return header_.top_count != 0; }
  /// The CPU structures the device copies (tests compare against them).
  [[nodiscard]] const NativeTracer& native() const { return native_; }

private:
  /// The top level's part of the arrays (rewritten alone when only instances moved).
  struct TopLayout {
    std::vector<GpuTopEntry> entries;
    std::vector<GpuNode> nodes;
    std::vector<std::uint32_t> indices;
  };
  void flatten(const SceneTables& tables);
  [[nodiscard]] TopLayout flatten_top() const;
  void upload_all(const SceneTables& tables);
  /// Rewrites the top level's entries, nodes and indices in place; false when its shape changed.
  bool upload_top();
  void write_header();
  /// Uploads `bytes` at `offset` of a binding's buffer (a whole-buffer write may grow it).
  void write(std::uint32_t binding, const void* data, std::size_t bytes, std::size_t offset = 0);
  template <class T> void write_vector(std::uint32_t binding, const std::vector<T>& data) {
    write(binding, data.data(), data.size() * sizeof(T));
  }

  Context& context_;
  GpuStructure structure_;
  NativeTracer native_;
  std::array<Buffer, kSceneBindings> buffers_;
  std::array<const Buffer*, kSceneBindings> bindings_{};
  bool uploaded_ = false;
  std::uint64_t synced_ = 0; ///< the layer's sync applied last (SceneLayer::syncs)
  GpuUploadStats upload_;
  std::uint32_t stack_depth_ = 0;
  // The flattened arrays as last uploaded (bindings 4–7) and where the top level lies in them.
  GpuSceneHeader header_{};
  std::vector<GpuNode> nodes_;
  std::vector<std::uint32_t> words_;
  std::vector<std::uint32_t> traced_;
  struct BlasPlace {
    std::uint32_t node_base, index_base, tri_base;
  };
  std::unordered_map<const accel::Bvh*, BlasPlace> blas_; ///< each distinct per-mesh BVH
  TopLayout top_;
};

} // namespace specula::gpu
