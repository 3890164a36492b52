#pragma once
/// \file
/// Path and shadow frames on the device (DeviceRenderer's stochastic modes):
/// path_integrator.cpp and shadow_integrator.cpp as kernels (shaders/path_*.comp), with the same
/// sample sequences (shaders/include/sampler.glsl is trace/sampler.h bit for bit), so CPU and GPU
/// images converge to the same reference. Each path is a record in a buffer (no recursion), run in
/// either execution style:
/// - wavefront: a chain of depths; per depth, trace passes over an indirect-dispatched queue until
///   every ray is done (a ray that uses up a pass's budget saves its walk and goes on in the next),
///   one shading dispatch (emission, shadow rays into the path's own slots, the sampled
///   continuation queued), shadow passes as the Whitted wavefront's (frame_shadow.comp), and a
///   gather adding the visible shadow rays in the CPU's order;
/// - single kernel (path_single.comp): one invocation walks its path to the end, the same shading
///   and gather in its own loop, dispatched again until every path has ended (a walk stopped by
///   the budget or its step bound keeps its state in the buffers and its trace in its own pool
///   slot), so its image is the wavefront's bit for bit.
/// A resolve then sums each pixel's samples. Paths are run in chunks of pixels × sample batches
/// that fit a storage buffer (and, single kernel, the state pool's one slot per path).

#include "specula/gpu/vk_context.h"
#include "specula/shared/frame_layout.h"

#include <cstdint>
#include <memory>

namespace specula {
class SceneLayer;
struct GuideBuffers;
struct TraceSettings;
} // namespace specula

namespace specula::gpu {

class GpuScene;
enum class Execution : std::uint8_t;

/// DeviceRenderer's frame buffers that the path kernels share (bindings 8-14).
struct FrameBuffers {
  Buffer* params;
  Buffer* materials;
  Buffer* lights;
  Buffer* normals;
  Buffer* counters;
  Buffer* image;
  Buffer* primary;
  Buffer* counters_host; ///< host-visible: each submit's commands copy the counters here
};

/// Saved traversal states of the frame kernels (shaders/include/trace_pool.glsl): pools of
/// `slots` slots, each a GpuTraceState and `stride` stack entries.
struct StatePool {
  Buffer states, stacks;
  std::uint32_t slots = 0;
  std::uint32_t stride = 0;
  /// Sizes `pools` pools for `rays` rays in flight each (fewer where a storage buffer would
  /// overflow, or past a cap: a ray that then finds its pool full starts over, counted), each
  /// with `stride` stack entries (GpuScene::stack_depth).
  void reserve(Context& context, std::uint32_t pools, std::uint64_t rays, std::uint32_t stride);
};

class DevicePath {
public:
  DevicePath(Context& context, const GpuScene& scene, Execution execution);
  ~DevicePath();
  DevicePath(const DevicePath&) = delete;
  DevicePath& operator=(const DevicePath&) = delete;

  /// Area-light samples per pixel a device shadow frame may take: path_shade draws them in one
  /// loop (with a binary search of the emitter table in each step), and lavapipe ends any loop
  /// silently once the 8 lanes of a SIMD vector have spent 65,535 iterations between them.
  /// Shadow frames asking more run on the CPU integrator (DeviceRenderer::supports).
  static constexpr std::uint32_t kMaxShadowSamples = 64;
  /// Samples of a pixel one resolve invocation sums in its loop, for the same reason.
  static constexpr std::uint32_t kMaxBatch = 256;

  /// Runs a path or shadow frame: `params` filled for the frame (camera, budget, lights), the
  /// tables uploaded, the counters zeroed; leaves the image, primary slots and counters in
  /// `frame`, and, given `guides`, the denoiser's guides there (from each pixel's first sample's
  /// primary hit, as the CPU integrators write them). Adds GPU time and dispatches.
  void render(const SceneLayer& layer, const TraceSettings& settings, GpuFrameParams params,
              const FrameBuffers& frame, double& gpu_ms, std::uint64_t& dispatches,
              GuideBuffers* guides = nullptr);

private:
  struct Features {
    bool shadow_mode, shadows, dielectrics, mirrors, area, guides;
    std::uint32_t lights, sampling;
    bool grid, top; ///< trace.glsl's grid walk and top level compiled in (frame_common.glsl)
    friend bool operator==(const Features&, const Features&) = default;
  };
  struct Pipelines;

  void upload_emitters(const SceneLayer& layer);
  void ensure_pipelines(const Features& features);

  Context& context_;
  const GpuScene& scene_;
  Execution execution_;
  std::unique_ptr<Pipelines> pipelines_;
  std::unique_ptr<Pipelines> previous_; ///< the set before the last change (DeviceRenderer's)
  Buffer paths_, hits_, queues_, shadows_, shadow_queues_, path_params_, emitters_,
      emitter_first_, sums_, sobol_, guides_;
  Buffer no_cache_; ///< bound at the cache's bindings 20-22, which path frames do not use
  StatePool pool_;
  std::uint64_t emitters_sync_ = 0;
  std::uint32_t emitter_count_ = 0;
};

} // namespace specula::gpu
