#include "specula/gpu/device_renderer.h"

#include "specula/cache/ray_cache.h"
#include "specula/core/error.h"
#include "specula/gpu/device_cache.h"
#include "specula/gpu/device_path.h"
#include "specula/gpu/shaders.h"
#include "specula/gpu/vulkan_tracer.h"
#include "specula/render/scene_layer.h"
#include "specula/scene/scene.h"
#include "specula/shared/cache_layout.h"
#include "specula/shared/frame_layout.h"
#include "specula/trace/camera_rays.h"
#include "specula/trace/render_frame.h"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <string>

namespace specula::gpu {
namespace {

static_assert(sizeof(GpuHit) == 32 && sizeof(vec3) == 12);

/// The push constants of every frame kernel (frame_wavefront.glsl's WavePush).
struct WavePush {
  std::uint32_t parity = 0;
  std::uint32_t depth = 0; ///< frame_args: the wave's index; frame_fold: the depth it folds
  std::uint32_t count = 0; ///< frame_fold: the end of its node range
  std::uint32_t first = 0; ///< frame_fold: the start of its node range
};

// Every depth the fold passes over has its wave's node mark.
static_assert(kWaveMarks >= kMaxTraceDepth);

/// Waves recorded per submit beyond the max_depth + 1 a tree needs (its last shadow rays).
constexpr std::uint32_t kExtraWaves = 1;
/// A frame whose rays are still queued after this many waves (or single-kernel dispatches) is
/// abandoned with an error: the traversal budget is too small for the scene.
constexpr std::uint32_t kMaxWaves = 4096;
/// Single kernel: dispatches per submit, and pixels per chunk (its stacks live in one buffer).
constexpr std::uint32_t kSingleRounds = 4;
constexpr std::uint32_t kChunkPixels = 16384;
/// Wavefront: node slots per pixel (rays of its tree); a tree that needs more is cut, counted
/// as dropped.
constexpr std::uint32_t kNodesPerPixel = 8;

std::uint32_t groups(std::uint32_t n) { return (n + 63) / 64; }

template <class T>
void upload_vector(Context& ctx, Buffer& buffer, const std::vector<T>& data) {
  ensure_size(ctx, buffer, data.size() * sizeof(T));
  if (!data.empty()) buffer.upload(data.data(), data.size() * sizeof(T));
}

} // namespace

struct DeviceRenderer::Pipelines {
  Features features;
  Pipeline args, eye, visibility, trace, shade, shadow, fold, single;
};

DeviceRenderer::DeviceRenderer(Context& context, const GpuScene& scene, Execution execution,
                               PrimaryVisibility primary)
    : context_(context), scene_(scene), execution_(execution),
      cache_(std::make_unique<DeviceCache>(context)), pool_(std::make_unique<StatePool>()) {
  if (primary != PrimaryVisibility::raster) return;
  if (!context.info().graphics)
    throw Error("vulkan", "rasterised primary visibility (--gpu-primary raster): device '" +
                              context.info().name + "' cannot draw on its compute queue");
  raster_ = std::make_unique<RasterPrimary>(context, scene);
}

DeviceRenderer::~DeviceRenderer() = default;

bool DeviceRenderer::supports(const TraceSettings& settings, RadianceHook* hook,
                              bool has_guides) const {
  // Path and shadow frames (DevicePath, either execution style) take no radiance hook, and
  // write the denoiser's guides when asked; other frames have no guides to write.
  if (settings.mode == TraceMode::Shadow && settings.shadow_samples > DevicePath::kMaxShadowSamples)
    return false;
  if (settings.mode == TraceMode::Path || settings.mode == TraceMode::Shadow)
    return hook == nullptr;
  if (has_guides) return false;
  return hook == nullptr || DeviceCache::store_of(hook) != nullptr;
}

std::uint64_t DeviceRenderer::cache_texels_uploaded() const { return cache_->texels_uploaded(); }

void DeviceRenderer::upload_tables(const SceneLayer& layer) {
  const SceneTables& t = layer.tables();
  const SceneDelta& d = layer.delta();
  // The delta says what changed since the previous sync: trusted only when this renderer saw
  // that one; otherwise (first frame, skipped syncs) everything goes up.
  const bool all = tables_sync_ == 0 || layer.syncs() != tables_sync_ + 1;
  if (tables_sync_ == layer.syncs()) return;
  if (all || d.materials_changed || !d.instances_added.empty() || !d.instances_removed.empty() ||
      d.static_rebuilt)
    upload_vector(context_, materials_, t.materials);
  if (all || d.lights_changed) upload_vector(context_, lights_, t.lights);
  if (all || d.geometry_relocated || d.static_rebuilt || !d.meshes_added.empty() ||
      !d.instances_added.empty() || t.normals.size() != normals_uploaded_) {
    upload_vector(context_, normals_, t.normals);
    normals_uploaded_ = t.normals.size();
  } else {
    // Deformed in place: only their own normals changed (a deforming mesh that gains normals
    // appends a range, which the size check above sends whole).
    for (const std::uint32_t slot : d.instances_deformed) {
      const GpuMesh& m = t.meshes[t.instances[slot].mesh];
      if (m.first_normal != kNoIndex)
        normals_.upload(&t.normals[m.first_normal], m.vertex_count * sizeof(vec3),
                        m.first_normal * sizeof(vec3));
    }
  }
  light_count_ = std::uint32_t(t.lights.size());
  tables_sync_ = layer.syncs();
}

void DeviceRenderer::ensure_pipelines(const Features& f) {
  if (pipelines_ && pipelines_->features == f) return;
  if (previous_ && previous_->features == f) {
    std::swap(pipelines_, previous_);
    return;
  }
  auto p = std::make_unique<Pipelines>();
  p->features = f;
  // frame_common.glsl's ids 0-6, path.glsl's 7-10 (absent from these kernels), then 11-12.
  const std::vector<std::uint32_t> spec = {f.whitted ? 1u : 0u, f.shadows ? 1u : 0u,
                                           f.dielectrics ? 1u : 0u, f.specular ? 1u : 0u,
                                           f.lights, f.cache ? 1u : 0u, raster_ ? 1u : 0u,
                                           0u, 0u, 0u, 0u, f.grid ? 1u : 0u, f.top ? 1u : 0u};
  const auto make = [&](const char* name) {
    return context_.make_pipeline({shader_spirv(name), kFramePoolBindings, sizeof(WavePush), spec,
                                   name, GpuScene::texel_bindings()});
  };
  if (execution_ == Execution::wavefront) {
    p->args = make("frame_args");
    p->eye = make("frame_eye");
    if (raster_) p->visibility = make("frame_visibility");
    p->trace = make("frame_trace");
    p->shade = make("frame_shade");
    p->shadow = make("frame_shadow");
    p->fold = make("frame_fold");
  } else {
    p->single = make("frame_single");
  }
  previous_ = std::move(pipelines_);
  pipelines_ = std::move(p);
}

void DeviceRenderer::ensure_frame_buffers(std::uint32_t pixels) {
  // Device-local: every invocation reads the parameters and adds to the counters (atomics on
  // host memory would cross the bus); the commands copy the counters to counters_host_.
  ensure_size(context_, params_, sizeof(GpuFrameParams));
  ensure_size(context_, counters_buffer_, sizeof(GpuFrameCounters));
  ensure_size(context_, counters_host_, sizeof(GpuFrameCounters), MemoryKind::host);
  // A window may still be presenting the last frame from image_ (in place, on a shared
  // device): its commands finish before the buffer is replaced.
  if (image_.valid() && image_.size() < VkDeviceSize(pixels) * 16) context_.wait_idle();
  ensure_size(context_, image_, VkDeviceSize(pixels) * 16);
  ensure_size(context_, primary_buffer_, VkDeviceSize(pixels) * 4);
  ensure_size(context_, unused_, 16);
}

void DeviceRenderer::ensure_buffers(std::uint32_t pixels, const Features& f) {
  const VkDeviceSize range = context_.info().max_storage_buffer_range;
  ensure_frame_buffers(pixels);
  if (execution_ == Execution::wavefront) {
    // Trees of per_pixel nodes for as many pixels as one storage buffer holds: a larger frame
    // is rendered in chunks of chunk_pixels_ (run_wavefront), each with every slot.
    const std::uint64_t per_pixel = f.whitted && f.specular ? kNodesPerPixel : 1;
    const std::uint64_t most = range / sizeof(GpuFrameNode);
    chunk_pixels_ = std::uint32_t(
        std::min<std::uint64_t>(pixels, std::max<std::uint64_t>(64, most / per_pixel / 64 * 64)));
    if (chunk_limit_ > 0) chunk_pixels_ = std::min(chunk_pixels_, chunk_limit_);
    node_capacity_ =
        std::uint32_t(std::min<std::uint64_t>(std::uint64_t(chunk_pixels_) * per_pixel, most));
    const std::uint64_t shadow_slots =
        f.whitted ? std::uint64_t(node_capacity_) * std::max(1u, f.lights) : 1;
    shadow_capacity_ =
        std::uint32_t(std::min<std::uint64_t>(shadow_slots, range / sizeof(GpuShadowRay)));
    ensure_size(context_, nodes_, VkDeviceSize(node_capacity_) * sizeof(GpuFrameNode));
    ensure_size(context_, hits_, VkDeviceSize(node_capacity_) * sizeof(GpuHit));
    ensure_size(context_, queues_, VkDeviceSize(node_capacity_) * 8);
    ensure_size(context_, shadows_, VkDeviceSize(shadow_capacity_) * sizeof(GpuShadowRay));
    ensure_size(context_, shadow_queues_, VkDeviceSize(shadow_capacity_) * 8);
    pool_->reserve(context_, 2, std::uint64_t(node_capacity_) + shadow_capacity_,
                   scene_.stack_depth());
  } else {
    chunk_pixels_ = std::min(pixels, kChunkPixels);
    ensure_size(context_, nodes_,
                VkDeviceSize(chunk_pixels_) * kStackFrames * sizeof(GpuStackFrame));
    ensure_size(context_, queues_, VkDeviceSize(chunk_pixels_) * 4);
    ensure_size(context_, hits_, 16);
    ensure_size(context_, shadows_, 16);
    ensure_size(context_, shadow_queues_, 16);
    pool_->reserve(context_, 1, chunk_pixels_, scene_.stack_depth()); // a slot per chunk pixel
  }
}


std::vector<const Buffer*> DeviceRenderer::bindings() const {
  std::vector<const Buffer*> b(scene_.bindings().begin(), scene_.bindings().end());
  for (const Buffer* own : {&params_, &materials_, &lights_, &normals_, &counters_buffer_, &image_,
                            &primary_buffer_, &nodes_, &hits_, &queues_, &shadows_,
                            &shadow_queues_})
    b.push_back(own);
  for (int k = 0; k < 3; ++k) b.push_back(cache_buffers_[k]);
  // Hybrid mode's visibility buffer and slot boxes (23-24), the rest of the path frames' range
  // (25-27), unused here, then the state pools.
  b.push_back(raster_ ? &raster_->visibility() : &unused_);
  b.push_back(raster_ ? &raster_->slot_boxes() : &unused_);
  while (b.size() < kFramePoolStatesBinding) b.push_back(&unused_);
  b.push_back(&pool_->states);
  b.push_back(&pool_->stacks);
  b.push_back(&unused_); // 30: the path frames' guides
  b.push_back(cache_buffers_[3]); // 31: the cubes' counts
  return b;
}

void DeviceRenderer::bind_cache(bool cache) {
  cache_buffers_[0] = cache ? &cache_->cubes() : &unused_;
  cache_buffers_[1] = cache ? &cache_->texels() : &unused_;
  cache_buffers_[2] = cache ? &cache_->records() : &unused_;
  cache_buffers_[3] = cache ? &cache_->counts() : &unused_;
}

void DeviceRenderer::record_start(Commands& cmd, const GpuFrameParams& params,
                                  const GpuFrameCounters& counters) const {
  cmd.update(params_, &params, sizeof params);
  cmd.update(counters_buffer_, &counters, sizeof counters);
  if (cache_bound()) cache_->record_start(cmd);
  cmd.barrier();
}

void DeviceRenderer::run_wavefront(const TraceSettings& settings, std::uint32_t pixels,
                                   GpuFrameParams params) {
  const Pipelines& p = *pipelines_;
  const std::vector<const Buffer*> buffers = bindings();
  const std::uint32_t batch =
      settings.mode == TraceMode::Cast ? 1 + kExtraWaves : settings.max_depth + 1 + kExtraWaves;
  const std::uint32_t deepest = settings.mode == TraceMode::Cast ? 0 : settings.max_depth;
  // A timestamp after each stage's dispatches (stage_ms_): a submit has at most the eye and
  // visibility stages and a batch of waves, or the folds, between its first and last.
  Commands cmd(context_, 4 + std::max(3 * batch + 2, deepest + 1));
  std::vector<std::pair<GpuStage, std::uint32_t>> stamps;
  const auto stamp = [&](GpuStage stage) { stamps.emplace_back(stage, cmd.timestamp()); };
  // After a submit: each stage's time from the timestamp before its own, the whole from `begin`.
  const auto settle = [&](std::uint32_t begin, std::uint32_t end) {
    std::uint32_t before = begin;
    for (const auto& [stage, at] : stamps) {
      stage_ms_[std::size_t(stage)] += cmd.elapsed_ms(before, at);
      before = at;
    }
    stamps.clear();
    gpu_ms_ += cmd.elapsed_ms(begin, end);
  };
  // A frame whose trees would outgrow the node buffer goes in chunks of pixels (ensure_buffers),
  // each with every node slot: its waves, then its fold. The counters of rays, cut, dropped and
  // records run on over the chunks; those of nodes and queues start again with each.
  for (std::uint32_t first_pixel = 0; first_pixel < pixels; first_pixel += chunk_pixels_) {
    const std::uint32_t chunk = std::min(chunk_pixels_, pixels - first_pixel);
    params.first_pixel = first_pixel;
    params.chunk_pixels = chunk;
    GpuFrameCounters init{};
    init.node_count = chunk;
    init.queue_count[0] = chunk;
    WavePush push;
    const std::uint32_t t0 = cmd.timestamp();
    if (first_pixel == 0) {
      record_start(cmd, params, init);
    } else {
      cmd.update(params_, &params, sizeof params);
      cmd.update(counters_buffer_, &init, offsetof(GpuFrameCounters, rays));
      cmd.update(counters_buffer_, &init.state_count, sizeof init.state_count,
                 offsetof(GpuFrameCounters, state_count));
      cmd.barrier();
    }
    cmd.dispatch(p.eye, buffers, &push, groups(chunk));
    cmd.barrier();
    stamp(GpuStage::Eye);
    ++dispatches_;
    if (raster_) {
      // Hybrid mode: the primary hits from the raster pass (the whole frame's, drawn once);
      // frame_trace skips the rays they settle.
      if (first_pixel == 0) {
        raster_->record(cmd);
        cmd.barrier();
      }
      cmd.dispatch(p.visibility, bindings(), &push, groups(chunk));
      cmd.barrier();
      stamp(GpuStage::Visibility);
      ++dispatches_;
    }
    std::uint32_t parity = 0;
    GpuFrameCounters c{};
    for (std::uint32_t waves = 0;;) {
      const std::uint32_t begin = waves == 0 ? t0 : cmd.timestamp();
      for (std::uint32_t w = 0; w < batch; ++w, parity ^= 1u) {
        push.parity = parity;
        push.depth = waves + w;
        cmd.dispatch(p.args, buffers, &push, 1);
        cmd.barrier();
        cmd.dispatch_indirect(p.trace, buffers, &push, counters_buffer_,
                              offsetof(GpuFrameCounters, ray_args));
        cmd.barrier();
        stamp(GpuStage::Trace);
        cmd.dispatch_indirect(p.shade, buffers, &push, counters_buffer_,
                              offsetof(GpuFrameCounters, ray_args));
        cmd.barrier();
        stamp(GpuStage::Shade);
        if (settings.mode == TraceMode::Whitted && settings.shadows && p.features.lights > 0) {
          cmd.dispatch_indirect(p.shadow, buffers, &push, counters_buffer_,
                                offsetof(GpuFrameCounters, shadow_args));
          cmd.barrier();
          stamp(GpuStage::Shadow);
        }
        dispatches_ += 1;
      }
      const std::uint32_t end = cmd.timestamp();
      record_counters_to_host(cmd);
      cmd.submit();
      settle(begin, end);
      waves += batch;
      std::memcpy(&c, counters_host_.mapped(), sizeof c);
      // The last wave appended to the queues of `parity`: empty means every ray is done.
      if (c.queue_count[parity] == 0 && c.shadow_queue_count[parity] == 0) break;
      if (waves >= kMaxWaves)
        throw Error("vulkan", "device frame: rays still queued after " + std::to_string(waves) +
                                  " waves (traversal budget " + std::to_string(budget_) +
                                  " too small for this scene)");
    }

    // The fold, deepest level first, each depth over the nodes that may have it: the primaries
    // (node i = the chunk's pixel i), or those spawned from wave d − 1's shading on
    // (kWaveMarks).
    const std::uint32_t nodes = std::min(c.node_count, node_capacity_);
    const std::uint32_t begin = cmd.timestamp();
    for (std::uint32_t d = deepest + 1; d-- > 0;) {
      const std::uint32_t first =
          d == 0 ? 0u : std::min(d - 1 < kWaveMarks ? c.wave_nodes[d - 1] : 0u, nodes);
      const std::uint32_t end = d == 0 ? std::min(chunk, nodes) : nodes;
      if (end <= first) continue;
      push = WavePush{0, d, end, first};
      cmd.dispatch(p.fold, buffers, &push, groups(end - first));
      cmd.barrier();
      stamp(GpuStage::Fold);
      ++dispatches_;
    }
    const std::uint32_t end = cmd.timestamp();
    record_counters_to_host(cmd);
    cmd.submit();
    settle(begin, end);
  }
  wave_chunks_ = (pixels + chunk_pixels_ - 1) / chunk_pixels_;
}

void DeviceRenderer::record_counters_to_host(Commands& cmd) const {
  cmd.barrier();
  cmd.copy(counters_buffer_, counters_host_, sizeof(GpuFrameCounters));
  if (cache_bound()) cache_->record_counts_to_host(cmd);
  cmd.host_barrier();
}

void DeviceRenderer::run_single(std::uint32_t pixels, GpuFrameParams params) {
  const Pipelines& p = *pipelines_;
  const std::vector<const Buffer*> buffers = bindings();
  const GpuFrameCounters init{};
  Commands cmd(context_, 4);
  const WavePush push;
  record_start(cmd, params, init);
  if (raster_) {
    // Hybrid mode: the whole frame's visibility buffer before the first walk.
    const std::uint32_t begin = cmd.timestamp();
    raster_->record(cmd);
    cmd.barrier();
    const std::uint32_t end = cmd.timestamp();
    cmd.submit();
    gpu_ms_ += cmd.elapsed_ms(begin, end);
  }
  for (std::uint32_t first = 0; first < pixels; first += chunk_pixels_) {
    params.first_pixel = first;
    params.chunk_pixels = std::min(chunk_pixels_, pixels - first);
    cmd.update(params_, &params, sizeof params);
    cmd.fill(queues_, 0xFFFFFFFFu, 0, VkDeviceSize(params.chunk_pixels) * 4); // kWalkNew
    cmd.barrier();
    for (std::uint32_t rounds = 0;;) {
      const std::uint32_t begin = cmd.timestamp();
      for (std::uint32_t r = 0; r < kSingleRounds; ++r) {
        if (r + 1 == kSingleRounds) {
          cmd.fill(counters_buffer_, 0, offsetof(GpuFrameCounters, pending), 4);
          cmd.barrier();
        }
        cmd.dispatch(p.single, buffers, &push, groups(params.chunk_pixels));
        cmd.barrier();
        ++dispatches_;
      }
      const std::uint32_t end = cmd.timestamp();
      record_counters_to_host(cmd);
      cmd.submit();
      gpu_ms_ += cmd.elapsed_ms(begin, end);
      rounds += kSingleRounds;
      GpuFrameCounters c{};
      std::memcpy(&c, counters_host_.mapped(), sizeof c);
      if (c.pending == 0) break;
      if (rounds >= kMaxWaves)
        throw Error("vulkan", "device frame: " + std::to_string(c.pending) +
                                  " pixels unfinished after " + std::to_string(rounds) +
                                  " dispatches (traversal budget " + std::to_string(budget_) +
                                  " too small for this scene)");
    }
  }
}

void DeviceRenderer::read_back(Framebuffer& out) const {
  if (out.width() != frame_.width || out.height() != frame_.height)
    throw Error("vulkan", "reading back a " + std::to_string(frame_.width) + "x" +
                              std::to_string(frame_.height) + " device frame into a " +
                              std::to_string(out.width()) + "x" + std::to_string(out.height()) +
                              " image");
  const std::size_t pixels = std::size_t(frame_.width) * frame_.height;
  std::span<vec3> px = out.pixels();
  // Straight from the staging copy into the image.
  image_.read(pixels * sizeof(vec4), 0, [&](const void* from) {
    const auto* image = static_cast<const vec4*>(from);
    for (std::size_t i = 0; i < pixels; ++i) px[i] = vec3(image[i]);
  });
  image_pending_ = false;
}

std::span<const std::uint32_t> DeviceRenderer::primary_instances() const {
  if (primary_pending_) {
    primary_.resize(std::size_t(frame_.width) * frame_.height);
    primary_buffer_.download(primary_.data(), primary_.size() * 4);
    primary_pending_ = false;
  }
  return primary_;
}

std::vector<GpuHit> DeviceRenderer::primary_hits() const {
  if (execution_ != Execution::wavefront)
    throw Error("vulkan", "primary hits are kept by wavefront device frames only");
  if (wave_chunks_ != 1)
    throw Error("vulkan",
                "primary hits are kept by wavefront frames of one chunk only (this one had " +
                    std::to_string(wave_chunks_) + ")");
  std::vector<GpuHit> hits(std::size_t(frame_.width) * frame_.height);
  if (!hits.empty()) hits_.download(hits.data(), hits.size() * sizeof(GpuHit));
  return hits;
}

void DeviceRenderer::render(const SceneLayer& layer, const Camera& camera,
                            const TraceSettings& settings, Framebuffer& out, FrameStats& stats,
                            GpuTraceCounters& counters, RadianceHook* hook,
                            GuideBuffers* guides) {
  if (!supports(settings, hook, guides != nullptr))
    throw Error("vulkan", std::string("device frames do not render mode ") +
                              trace_mode_name(settings.mode) +
                              (hook != nullptr ? " with this radiance hook" : ""));
  cache::RayCacheStore* store = hook != nullptr ? DeviceCache::store_of(hook) : nullptr;
  const auto start = std::chrono::steady_clock::now();
  // The last frame kept on the device is overwritten from here on: no longer presentable.
  image_pending_ = false;
  const std::uint32_t width = out.width(), height = out.height();
  const std::uint32_t pixels = width * height;
  if (store != nullptr) store->begin_frame(width, height, settings.mode);
  const std::uint64_t submits = context_.submits();
  try {
    upload_tables(layer);
    const SceneFeatures& scene = layer.emitters().features();
    const bool whitted = settings.mode == TraceMode::Whitted;
    const bool stochastic =
        settings.mode == TraceMode::Path || settings.mode == TraceMode::Shadow;
    const bool specular = whitted && (scene.mirrors || scene.dielectrics);
    // Cubes only matter where rays leave objects: the cache code is compiled in for those frames.
    // A store whose cubes are all off (auto) wants no leaving rays: none are recorded.
    const bool cache =
        specular && store != nullptr && store->cube_count() > 0 && store->wants_leaving();
    if (stochastic) {
      ensure_frame_buffers(pixels);
    } else {
      const Features f{whitted, whitted && settings.shadows, whitted && scene.dielectrics,
                       specular, cache, light_count_, scene_.structure() == GpuStructure::grid,
                       scene_.has_top_level()};
      ensure_pipelines(f);
      ensure_buffers(pixels, f);
    }
    if (cache) {
      cache_->upload(*store, std::uint32_t(layer.tables().instances.size()),
                     store->wants_lookups());
      // Each traced or served ray is at most one record: as many as the frame's node slots
      // (kNodesPerPixel a pixel), in one chunk or several.
      cache_->reserve_records(pixels * kNodesPerPixel);
    }
    bind_cache(cache);

    const CameraRays rays(camera, width, height, layer.render_origin());
    GpuFrameParams params{};
    params.camera_origin = rays.origin;
    params.camera_forward = rays.forward;
    params.camera_right = rays.right;
    params.camera_up = rays.up;
    params.inv_width = rays.inv_width;
    params.inv_height = rays.inv_height;
    params.width = width;
    params.height = height;
    params.background = settings.background;
    params.min_weight = settings.min_weight;
    params.max_depth = settings.max_depth;
    params.light_count = light_count_;
    params.node_capacity = node_capacity_;
    params.shadow_capacity = shadow_capacity_;
    params.budget = budget_;
    params.pixel_count = pixels;
    params.first_pixel = 0;
    params.chunk_pixels = pixels;
    params.record_capacity = cache ? cache_->record_capacity() : 0;
    params.stack_stride = pool_->stride;
    params.pool_slots = pool_->slots;
    if (raster_ && !stochastic) raster_->prepare(layer, rays, width, height);

    gpu_ms_ = 0.0;
    stage_ms_ = GpuStageTimes{};
    dispatches_ = 0;
    if (stochastic) {
      const GpuFrameCounters zero{};
      counters_buffer_.upload(&zero, sizeof zero);
      if (!path_) path_ = std::make_unique<DevicePath>(context_, scene_, execution_);
      path_->render(layer, settings, params,
                    FrameBuffers{&params_, &materials_, &lights_, &normals_, &counters_buffer_,
                                 &image_, &primary_buffer_, &counters_host_},
                    gpu_ms_, dispatches_, guides);
    } else if (execution_ == Execution::wavefront)
      run_wavefront(settings, pixels, params);
    else
      run_single(pixels, params);

    // The frames copied their counters to the host with their last commands.
    GpuFrameCounters c{};
    std::memcpy(&c, counters_host_.mapped(), sizeof c);
    frame_ = DeviceFrame{&context_, &image_, width, height};
    primary_pending_ = true;
    // Cast and Whitted frames may stay on the device (presented in place); path and shadow
    // frames are averaged on the host.
    image_pending_ = keep_on_device_ && !stochastic;
    if (!image_pending_) read_back(out);

    stats.rays = RayCounts{};
    for (int k = 0; k < kRayKindCount; ++k) stats.rays.count[k] = c.rays[k];
    stats.rays.dropped = c.dropped;
    stats.rays.nonfinite = c.nonfinite;
    counters.rays = stats.rays.total();
    counters.resumed = c.resumed;
    counters.cut = c.cut;
    counters.retraced = c.retraced;
    counters.restarted = c.restarted;
    counters.dispatches = dispatches_;
    counters.gpu_ms = gpu_ms_;
    counters.stage_ms = stage_ms_;
    cache_records_ = cache ? c.records : 0;
    cache_mismatches_ = cache ? cache_->deliver(*store, layer.tables(), c.records) : 0;
    counters.submits = context_.submits() - submits;
  } catch (const GpuError& e) {
    throw GpuError(std::string("vulkan device frame (") + trace_mode_name(settings.mode) + ", " +
                       (execution_ == Execution::wavefront ? "wavefront" : "single kernel") +
                       "): " + e.what(),
                   e.result());
  }
  stats.trace_ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  if (store != nullptr) store->end_frame(stats.trace_ms, stats.rays.total());
}

} // namespace specula::gpu
