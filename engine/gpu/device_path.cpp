#include "specula/gpu/device_path.h"

#include "specula/core/error.h"
#include "specula/gpu/gpu_scene.h"
#include "specula/gpu/shaders.h"
#include "specula/gpu/vulkan_tracer.h"
#include "specula/image/denoise.h"
#include "specula/render/scene_layer.h"
#include "specula/shared/path_layout.h"
#include "specula/trace/render_frame.h"
#include "specula/trace/sampler.h"

#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

namespace specula::gpu {
namespace {

static_assert(sizeof(EmitterTriangle) == sizeof(GpuEmitter) &&
              offsetof(EmitterTriangle, normal) == offsetof(GpuEmitter, normal) &&
              offsetof(EmitterTriangle, emission) == offsetof(GpuEmitter, emission));
static_assert(sizeof(sobol_detail::kByteTables) == 4 * 4 * 256 * sizeof(std::uint32_t));
static_assert(std::uint32_t(LightSampling::Mis) == kSamplingMis &&
              std::uint32_t(LightSampling::Bsdf) == kSamplingBsdf &&
              std::uint32_t(LightSampling::Light) == kSamplingLight);

/// path.glsl's PathPush, the size of frame_wavefront.glsl's WavePush (for frame_shadow).
struct PathPush {
  std::uint32_t parity = 0;
  std::uint32_t depth = 0;
  std::uint32_t count = 0;
  std::uint32_t unused = 0; ///< WavePush's fold range start
};

/// Most paths in flight (one chunk): 24 MiB of records; fewer where the shadow slots would
/// outgrow a storage buffer.
constexpr std::uint32_t kMaxPaths = 1u << 18;
/// Trace (or shadow) passes per submit: the first finishes every ray unless the budget is small.
constexpr std::uint32_t kPasses = 2;
/// Single kernel: dispatches per submit (most paths end within the first).
constexpr std::uint32_t kSingleRounds = 2;
/// Passes after which a depth whose rays are still queued (single kernel: dispatches after which
/// a batch's paths are still going) is abandoned with an error.
constexpr std::uint32_t kMaxPasses = 4096;

std::uint32_t groups(std::uint32_t n) { return (n + 63) / 64; }

/// Slots per state pool at most: two such pools take 12 MiB of states and 1 MiB per stack entry;
/// the default budget leaves far fewer rays than that out of budget at once.
constexpr std::uint64_t kMaxPoolSlots = 1u << 16;

} // namespace

void StatePool::reserve(Context& context, std::uint32_t pools, std::uint64_t rays,
                        std::uint32_t stack_stride) {
  const VkDeviceSize range = context.info().max_storage_buffer_range;
  const std::uint64_t entries = std::max(1u, stack_stride);
  const std::uint64_t n = std::min<std::uint64_t>(
      {std::max<std::uint64_t>(1, rays), kMaxPoolSlots, range / (pools * sizeof(GpuTraceState)),
       range / (pools * entries * 8)});
  slots = std::uint32_t(n);
  stride = stack_stride;
  ensure_size(context, states, pools * n * sizeof(GpuTraceState));
  ensure_size(context, stacks, pools * n * entries * 8);
}

struct DevicePath::Pipelines {
  Features features;
  Pipeline eye, args, trace, shade, shadow, gather, resolve, single;
};

DevicePath::DevicePath(Context& context, const GpuScene& scene, Execution execution)
    : context_(context), scene_(scene), execution_(execution) {}

DevicePath::~DevicePath() = default;

void DevicePath::upload_emitters(const SceneLayer& layer) {
  if (emitters_sync_ == layer.syncs() && emitters_.valid()) return;
  const std::vector<EmitterTriangle>& triangles = layer.emitters().triangles();
  ensure_size(context_, emitters_, triangles.size() * sizeof(GpuEmitter));
  if (!triangles.empty()) emitters_.upload(triangles.data(), triangles.size() * sizeof(GpuEmitter));
  // EmitterTable::find's per-instance entry: an emitting instance's triangles are consecutive
  // from its primitive 0.
  std::vector<std::uint32_t> first(layer.tables().instances.size(), kNoIndex);
  for (std::size_t k = 0; k < triangles.size(); ++k)
    if (triangles[k].primitive == 0) first[triangles[k].instance] = std::uint32_t(k);
  ensure_size(context_, emitter_first_, first.size() * 4);
  if (!first.empty()) emitter_first_.upload(first.data(), first.size() * 4);
  emitter_count_ = std::uint32_t(triangles.size());
  emitters_sync_ = layer.syncs();
  if (!sobol_.valid()) {
    ensure_size(context_, sobol_, sizeof(sobol_detail::kByteTables));
    sobol_.upload(sobol_detail::kByteTables.data(), sizeof(sobol_detail::kByteTables));
  }
}

void DevicePath::ensure_pipelines(const Features& f) {
  if (pipelines_ && pipelines_->features == f) return;
  if (previous_ && previous_->features == f) {
    std::swap(pipelines_, previous_);
    return;
  }
  auto p = std::make_unique<Pipelines>();
  p->features = f;
  // frame_common.glsl's ids 0-6 (0, 3, 5 the cache and 6 hybrid mode unused here), path.glsl's
  // 7-10, frame_common.glsl's 11-12, path.glsl's 13.
  const std::vector<std::uint32_t> spec = {
      0u, f.shadows ? 1u : 0u, f.dielectrics ? 1u : 0u, 0u, f.lights, 0u, 0u, f.area ? 1u : 0u,
      f.mirrors ? 1u : 0u, f.shadow_mode ? 1u : 0u, f.sampling, f.grid ? 1u : 0u,
      f.top ? 1u : 0u, f.guides ? 1u : 0u};
  const auto make = [&](const char* name) {
    return context_.make_pipeline({shader_spirv(name), kFramePoolBindings, sizeof(PathPush), spec,
                                   name, GpuScene::texel_bindings()});
  };
  p->eye = make("path_eye");
  p->resolve = make("path_resolve");
  if (execution_ == Execution::wavefront) {
    p->args = make("path_args");
    p->trace = make("path_trace");
    p->shade = make("path_shade");
    p->shadow = make("frame_shadow");
    p->gather = make("path_gather");
  } else {
    p->single = make("path_single");
  }
  previous_ = std::move(pipelines_);
  pipelines_ = std::move(p);
}

void DevicePath::render(const SceneLayer& layer, const TraceSettings& settings,
                        GpuFrameParams params, const FrameBuffers& frame, double& gpu_ms,
                        std::uint64_t& dispatches, GuideBuffers* guides) {
  upload_emitters(layer);
  const SceneFeatures& scene = layer.emitters().features();
  const bool shadow_mode = settings.mode == TraceMode::Shadow;
  const bool area = scene.area_lights && (!shadow_mode || settings.shadow_samples > 0);
  const Features f{shadow_mode,
                   settings.shadows,
                   scene.dielectrics && !shadow_mode,
                   scene.mirrors && !shadow_mode,
                   area,
                   guides != nullptr,
                   params.light_count,
                   std::uint32_t(settings.sampling),
                   scene_.structure() == GpuStructure::grid,
                   scene_.has_top_level()};
  ensure_pipelines(f);
  const Pipelines& p = *pipelines_;

  const std::uint32_t pixels = params.pixel_count;
  const std::uint32_t samples = shadow_mode && area ? settings.shadow_samples : 0;
  const std::uint32_t slots = params.light_count + (shadow_mode ? samples : 1);
  const std::uint32_t spp = shadow_mode ? 1 : std::max(1u, settings.spp);
  const VkDeviceSize range = context_.info().max_storage_buffer_range;
  const std::uint64_t fit = std::min<std::uint64_t>(
      {kMaxPaths, range / sizeof(GpuPath), range / (sizeof(GpuShadowRay) * std::max(1u, slots))});
  std::uint32_t max_paths = std::uint32_t(std::max<std::uint64_t>(1, fit));
  const bool single = execution_ == Execution::single_kernel;
  if (single) {
    // One pool slot per path in flight: a chunk is no larger than the pool.
    pool_.reserve(context_, 1, max_paths, scene_.stack_depth());
    max_paths = std::min(max_paths, pool_.slots);
  }
  const std::uint32_t batch =
      std::clamp(max_paths / std::max(1u, pixels), 1u, std::min(spp, kMaxBatch));
  const std::uint32_t chunk = std::max(1u, std::min(pixels, max_paths / batch));
  const std::uint32_t capacity = chunk * batch;
  const std::uint32_t shadow_capacity = capacity * std::max(1u, slots);
  ensure_size(context_, paths_, VkDeviceSize(capacity) * sizeof(GpuPath));
  ensure_size(context_, hits_, VkDeviceSize(capacity) * sizeof(GpuHit));
  ensure_size(context_, queues_, VkDeviceSize(capacity) * 8); // single kernel: 4 B cursors
  ensure_size(context_, shadows_, VkDeviceSize(shadow_capacity) * sizeof(GpuShadowRay));
  ensure_size(context_, shadow_queues_, single ? 16 : VkDeviceSize(shadow_capacity) * 8);
  ensure_size(context_, sums_, VkDeviceSize(pixels) * 16);
  ensure_size(context_, path_params_, sizeof(GpuPathParams)); // written in the command stream
  ensure_size(context_, no_cache_, 16);
  ensure_size(context_, guides_, guides != nullptr ? VkDeviceSize(pixels) * sizeof(GpuGuide) : 16);
  params.node_capacity = capacity;
  params.shadow_capacity = shadow_capacity;
  if (!single)
    pool_.reserve(context_, 2, std::uint64_t(capacity) + shadow_capacity, scene_.stack_depth());
  params.stack_stride = pool_.stride;
  params.pool_slots = pool_.slots;
  frame.params->upload(&params, sizeof params);

  std::vector<const Buffer*> buffers(scene_.bindings().begin(), scene_.bindings().end());
  for (const Buffer* b :
       {frame.params,  frame.materials, frame.lights,    frame.normals, frame.counters,
        frame.image,   frame.primary,   &paths_,         &hits_,        &queues_,
        &shadows_,     &shadow_queues_, &no_cache_,      &no_cache_,    &no_cache_,
        &path_params_, &emitters_,      &emitter_first_, &sums_,        &sobol_,
        &pool_.states, &pool_.stacks,   &guides_,        &no_cache_})
    buffers.push_back(b);

  Commands cmd(context_, 4);
  // One timestamp pair per submit: `mark` opens one before the first command recorded after a
  // submit.
  std::uint32_t begin = 0;
  bool open = false;
  const auto mark = [&] {
    if (!open) begin = cmd.timestamp();
    open = true;
  };
  const auto submit = [&] {
    const std::uint32_t end = cmd.timestamp();
    cmd.barrier();
    cmd.copy(*frame.counters, *frame.counters_host, sizeof(GpuFrameCounters));
    cmd.host_barrier();
    cmd.submit();
    gpu_ms += cmd.elapsed_ms(begin, end);
    open = false;
    GpuFrameCounters c{};
    std::memcpy(&c, frame.counters_host->mapped(), sizeof c);
    return c;
  };
  // Passes of the trace kernel `k` (queue `which`: 0 paths, 1 shadow rays) until its queue is
  // empty; the first pass reads queue 0.
  const auto passes = [&](const Pipeline& k, std::uint32_t which, VkDeviceSize args) {
    std::uint32_t parity = 0;
    for (std::uint32_t done = 0;;) {
      mark();
      for (std::uint32_t n = 0; n < kPasses; ++n, parity ^= 1u) {
        const PathPush push{parity, 0, which};
        cmd.dispatch(p.args, buffers, &push, 1);
        cmd.barrier();
        cmd.dispatch_indirect(k, buffers, &push, *frame.counters, args);
        cmd.barrier();
        ++dispatches;
      }
      const GpuFrameCounters c = submit();
      done += kPasses;
      const std::uint32_t left = which == 0 ? c.queue_count[parity] : c.shadow_queue_count[parity];
      if (left == 0) return c;
      if (done >= kMaxPasses)
        throw Error("vulkan", "device path frame: rays still queued after " +
                                  std::to_string(done) + " passes (traversal budget " +
                                  std::to_string(params.budget) + " too small for this scene)");
    }
  };

  const std::uint32_t max_depth = shadow_mode ? 0 : settings.max_depth;
  for (std::uint32_t first_pixel = 0; first_pixel < pixels; first_pixel += chunk) {
    const std::uint32_t chunk_pixels = std::min(chunk, pixels - first_pixel);
    for (std::uint32_t first = 0; first < spp; first += batch) {
      const std::uint32_t count = std::min(batch, spp - first);
      GpuPathParams pp{};
      pp.path_count = chunk_pixels * count;
      pp.batch = count;
      pp.first_pixel = first_pixel;
      pp.first_sample = first;
      pp.sample_offset = settings.sample_offset;
      pp.seed = settings.seed;
      pp.spp = spp;
      pp.shadow_samples = samples;
      pp.shadow_slots = std::max(1u, slots);
      pp.emitter_count = emitter_count_;
      pp.last_batch = first + count >= spp ? 1u : 0u;
      mark();
      cmd.update(path_params_, &pp, sizeof pp);
      const std::uint32_t all = groups(pp.path_count);
      // The eye kernel queues every path (queue 0) and empties queue 1.
      cmd.fill(*frame.counters, 0, offsetof(GpuFrameCounters, queue_count), 16);
      cmd.barrier();
      const PathPush start{};
      cmd.dispatch(p.eye, buffers, &start, all);
      cmd.barrier();
      if (single) {
        // The eye kernel's queue entries become the walks' shadow cursors (0: none traced).
        cmd.fill(queues_, 0, 0, VkDeviceSize(pp.path_count) * 4);
        cmd.barrier();
        for (std::uint32_t rounds = 0;;) {
          mark();
          for (std::uint32_t r = 0; r < kSingleRounds; ++r) {
            if (r + 1 == kSingleRounds) {
              cmd.fill(*frame.counters, 0, offsetof(GpuFrameCounters, pending), 4);
              cmd.barrier();
            }
            cmd.dispatch(p.single, buffers, &start, all);
            cmd.barrier();
            ++dispatches;
          }
          const GpuFrameCounters c = submit();
          rounds += kSingleRounds;
          if (c.pending == 0) break;
          if (rounds >= kMaxPasses)
            throw Error("vulkan", "device path frame: " + std::to_string(c.pending) +
                                      " paths unfinished after " + std::to_string(rounds) +
                                      " single-kernel dispatches (traversal budget " +
                                      std::to_string(params.budget) + " too small for this scene)");
        }
      }
      const std::uint32_t queued = single ? 0 : pp.path_count;
      cmd.fill(*frame.counters, queued, offsetof(GpuFrameCounters, queue_count), 4);
      cmd.barrier();
      for (std::uint32_t depth = 0; !single && depth <= max_depth; ++depth) {
        passes(p.trace, 0, offsetof(GpuFrameCounters, ray_args));
        // Shading appends to queue 0 of either kind.
        mark();
        cmd.fill(*frame.counters, 0, offsetof(GpuFrameCounters, queue_count), 16);
        cmd.barrier();
        const PathPush shade{0, depth, 0};
        cmd.dispatch(p.shade, buffers, &shade, all);
        cmd.barrier();
        const GpuFrameCounters c = passes(p.shadow, 1, offsetof(GpuFrameCounters, shadow_args));
        mark();
        cmd.dispatch(p.gather, buffers, &start, all);
        cmd.barrier();
        if (c.queue_count[0] == 0) break; // every path ended
      }
      mark();
      cmd.dispatch(p.resolve, buffers, &start, groups(chunk_pixels));
      cmd.barrier();
      submit();
    }
  }
  if (guides != nullptr) {
    std::vector<GpuGuide> g(pixels);
    guides_.download(g.data(), g.size() * sizeof(GpuGuide));
    guides->resize(pixels);
    for (std::uint32_t i = 0; i < pixels; ++i) {
      guides->albedo[i] = g[i].albedo;
      guides->normal[i] = g[i].normal;
      guides->depth[i] = g[i].depth;
    }
  }
}

} // namespace specula::gpu
