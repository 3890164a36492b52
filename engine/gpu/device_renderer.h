#pragma once
/// \file
/// Whole frames on the device: the streaming ray tracer's kernels (Purcell et al. 2002) — eye-ray
/// generation, traversal + intersection, shadow rays, shading that emits secondary rays with
/// weights (no recursion) — over the scene GpuScene holds, for cast and Whitted mode, in one of
/// two execution styles (VulkanTracer's Execution), both giving the same image:
///   - wavefront (shaders/frame_{eye,args,trace,shade,shadow,fold}.comp): one dispatch per stage,
///     sizes read by vkCmdDispatchIndirect from atomic queue counters; every ray of a pixel's
///     Whitted tree is a node appended to one buffer, shadow rays own slots in another, and after
///     the last wave a fold per depth (deepest first) sums each tree as the CPU does;
///   - single kernel (shaders/frame_single.comp): one invocation per pixel walks its tree depth
///     first over a fixed stack of frames in a buffer (shaders/shared/frame_layout.h).
/// The shading mirrors engine/trace (shaders/include/shading.glsl). Loops are bounded for
/// lavapipe's silent loop cap: every trace gets a per-dispatch budget; a ray (wavefront) or a
/// walk (single kernel) that uses it up is resumed by a later dispatch, its trace from the saved
/// traversal state (shaders/include/trace_pool.glsl), and rays the driver cut are counted
/// (GpuTraceCounters::cut, must be 0). In hybrid mode (PrimaryVisibility::raster) the primary
/// hits come from a raster pass (raster_primary.h) where it settles them.

#include "specula/gpu/gpu_scene.h"
#include "specula/gpu/raster_primary.h"
#include "specula/gpu/vk_context.h"
#include "specula/shared/frame_layout.h"
#include "specula/trace/stats.h"

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace specula {
class RadianceHook;
struct GuideBuffers;
class SceneLayer;
class Framebuffer;
struct Camera;
struct TraceSettings;
struct FrameStats;
} // namespace specula

namespace specula::gpu {

enum class Execution : std::uint8_t;

/// A frame left on the device (DeviceRenderer::set_keep_frames_on_device): width × height
/// linear radiance values, one vec4 each (alpha unused), row major from the top row, in
/// `radiance` on `context`'s device. Valid until the next frame is rendered.
struct DeviceFrame {
  const Context* context = nullptr;
  const Buffer* radiance = nullptr;
  std::uint32_t width = 0, height = 0;
};

struct GpuTraceCounters;
class DeviceCache;
class DevicePath;
struct StatePool;

class DeviceRenderer {
public:
  /// `primary` raster (hybrid mode) needs a device that draws: throws specula::Error otherwise.
  DeviceRenderer(Context& context, const GpuScene& scene, Execution execution,
                 PrimaryVisibility primary = PrimaryVisibility::trace);
  ~DeviceRenderer();
  DeviceRenderer(const DeviceRenderer&) = delete;
  DeviceRenderer& operator=(const DeviceRenderer&) = delete;

  /// Whether these settings run on the device: cast and Whitted with no radiance hook or a
  /// ray-cache store the device can serve (DeviceCache::store_of), and no denoiser guides; path
  /// and shadow in either execution style (DevicePath), with or without guides, without a hook,
  /// shadow with at most DevicePath::kMaxShadowSamples area-light samples.
  [[nodiscard]] bool supports(const TraceSettings& settings, RadianceHook* hook,
                              bool has_guides) const;
  /// Renders one frame of `layer` (GpuScene already updated from it) into `out`; `stats` gets the
  /// ray counts and trace_ms, `counters` the device's counts and GPU time. A ray-cache `hook`
  /// gets the frame as from render_frame (begin_frame, lookups, leaving, end_frame); path and
  /// shadow frames write `guides` when given. Throws GpuError (device_lost() for a lost device)
  /// naming the device frame.
  void render(const SceneLayer& layer, const Camera& camera, const TraceSettings& settings,
              Framebuffer& out, FrameStats& stats, GpuTraceCounters& counters,
              RadianceHook* hook = nullptr, GuideBuffers* guides = nullptr);

  /// Where every leaving ray is recorded (DeviceCache::Records::every): the last frame's
  /// ray-cache records whose device answer differed from the store's replayed lookup, and cubes
  /// whose lookup counts did (must be 0); texels uploaded for it.
  [[nodiscard]] std::uint64_t cache_mismatches() const { return cache_mismatches_; }
  [[nodiscard]] std::uint64_t cache_texels_uploaded() const;
  /// Leaving rays the last frame recorded for the store.
  [[nodiscard]] std::uint32_t cache_records() const { return cache_records_; }
  /// The device copy of the ray-cache store (which leaving rays it records: set_records).
  [[nodiscard]] DeviceCache& cache() { return *cache_; }

  /// The instance slot each pixel's primary ray hit in the last frame (kNoIndex: a miss), row
  /// major: for comparing primary visibility with the CPU backends (read back on first use).
  [[nodiscard]] std::span<const std::uint32_t> primary_instances() const;

  /// Cast and Whitted frames stay on the device instead of being read into render()'s `out`
  /// (which is then left as it was): device_frame() hands the image to a presenter on the same
  /// device (present::Window, Offscreen), read_back() copies it to the host when asked.
  void set_keep_frames_on_device(bool keep) { keep_on_device_ = keep; }
  /// The last frame while it is on the device only (kept there and not read back yet).
  [[nodiscard]] const DeviceFrame* device_frame() const {
    return image_pending_ ? &frame_ : nullptr;
  }
  /// Copies the last frame into `out` (its size); no longer on the device only after.
  void read_back(Framebuffer& out) const;
  /// Each pixel's primary hit in the last frame, row major, read back from the device
  /// (wavefront frames of one chunk only: throws specula::Error otherwise): traced and rasterised
  /// primary visibility compared hit by hit.
  [[nodiscard]] std::vector<GpuHit> primary_hits() const;

  /// Traversal iterations one invocation may spend per dispatch (default kDefaultBudget); lower
  /// values force resumption (tests).
  void set_budget(std::uint32_t budget) { budget_ = budget; }
  /// For tests: wavefront frames go in chunks of at most `pixels` (0: as the node buffer
  /// allows), as a frame too large for one storage buffer of nodes would.
  void set_chunk_limit(std::uint32_t pixels) { chunk_limit_ = pixels; }
  /// Chunks of pixels the latest wavefront frame went in.
  [[nodiscard]] std::uint32_t wave_chunks() const { return wave_chunks_; }
  static constexpr std::uint32_t kDefaultBudget = 6144;

private:
  struct Pipelines;
  struct Features {
    bool whitted, shadows, dielectrics, specular, cache;
    std::uint32_t lights;
    bool grid, top; ///< trace.glsl's grid walk and top level compiled in (frame_common.glsl)
    friend bool operator==(const Features&, const Features&) = default;
  };

  void upload_tables(const SceneLayer& layer);
  void ensure_pipelines(const Features& features);
  void ensure_frame_buffers(std::uint32_t pixels);
  void ensure_buffers(std::uint32_t pixels, const Features& features);
  /// `params`: the frame's, written by its first commands (record_start), as in run_single;
  /// the frame in chunks of chunk_pixels_ where its trees would outgrow the node buffer.
  void run_wavefront(const TraceSettings& settings, std::uint32_t pixels, GpuFrameParams params);
  /// `params`: the frame's (the chunks' first pixel and size are set in the commands).
  void run_single(std::uint32_t pixels, GpuFrameParams params);
  /// Records the copy of the counters into counters_host_ (read once the submit has finished),
  /// and of the cubes' counts where the frame has cubes (DeviceCache::deliver reads them).
  void record_counters_to_host(Commands& cmd) const;
  void bind_cache(bool cache);
  [[nodiscard]] bool cache_bound() const {
    return cache_buffers_[3] != nullptr && cache_buffers_[3] != &unused_;
  }
  /// Records what a frame's first commands do, with no submit of their own: the parameters and
  /// the counters' start written in the command stream, the cube table written and the cubes'
  /// counts zeroed where the frame has cubes (DeviceCache::record_start); then a barrier.
  void record_start(Commands& cmd, const GpuFrameParams& params,
                    const GpuFrameCounters& counters) const;
  /// Every frame kernel's buffers, bindings 0 to kFramePoolBindings - 1 (frame_layout.h), with
  /// `unused_` where the frame has no cubes or no visibility buffer.
  [[nodiscard]] std::vector<const Buffer*> bindings() const;

  Context& context_;
  const GpuScene& scene_;
  Execution execution_;
  std::uint32_t budget_ = kDefaultBudget;
  std::unique_ptr<Pipelines> pipelines_;
  /// The set used before the last change, kept so that a scene whose top level comes and goes
  /// switches between two sets instead of rebuilding each time.
  std::unique_ptr<Pipelines> previous_;
  std::unique_ptr<DeviceCache> cache_;
  const Buffer* cache_buffers_[4] = {nullptr, nullptr, nullptr, nullptr}; ///< bindings 20-22, 31
  std::uint64_t cache_mismatches_ = 0;
  std::uint32_t cache_records_ = 0;
  std::unique_ptr<DevicePath> path_; ///< path and shadow frames, made on first use
  std::unique_ptr<RasterPrimary> raster_; ///< hybrid mode only
  // Tables at bindings 8.. (frame_layout.h).
  Buffer params_, materials_, lights_, normals_, counters_buffer_, image_, primary_buffer_;
  Buffer counters_host_; ///< host-visible: the counters as the last submit left them
  Buffer nodes_, hits_, queues_, shadows_, shadow_queues_;
  Buffer unused_; ///< 16 bytes, bound where a frame has no cubes or no visibility buffer
  std::unique_ptr<StatePool> pool_; ///< saved traversal states (trace_pool.glsl)
  std::uint64_t tables_sync_ = 0; ///< SceneLayer::syncs() of the tables uploaded (0: none)
  std::size_t normals_uploaded_ = 0; ///< size of the normals pool last uploaded whole
  /// chunk_pixels_: pixels per chunk (single kernel: its stacks; wavefront: node_capacity_ /
  /// kNodesPerPixel where the frame's trees would outgrow one storage buffer, else the frame).
  std::uint32_t node_capacity_ = 0, shadow_capacity_ = 0, chunk_pixels_ = 0;
  std::uint32_t wave_chunks_ = 0; ///< chunks of the latest wavefront frame
  std::uint32_t chunk_limit_ = 0; ///< set_chunk_limit
  std::uint32_t light_count_ = 0;
  std::uint32_t max_depth_ = 0;
  mutable std::vector<std::uint32_t> primary_;
  DeviceFrame frame_; ///< the last frame: where it is, its size
  bool keep_on_device_ = false;
  mutable bool image_pending_ = false;   ///< the last frame is in image_ only
  mutable bool primary_pending_ = false; ///< primary_ not yet read from primary_buffer_
  double gpu_ms_ = 0.0;
  GpuStageTimes stage_ms_{}; ///< wavefront cast and Whitted frames: gpu_ms_ by stage
  std::uint64_t dispatches_ = 0;
};

} // namespace specula::gpu
