#include "specula/gpu/vulkan_tracer.h"

#include "specula/core/assert.h"
#include "specula/core/error.h"
#include "specula/gpu/device_renderer.h"
#include "specula/gpu/shaders.h"
#include "specula/render/scene_layer.h"
#include "specula/shared/gpu_scene_layout.h"
#include "specula/trace/camera_rays.h"
#include "specula/trace/packet_tile.h"
#include "specula/trace/render_frame.h"

#include <algorithm>
#include <cstring>
#include <limits>
#include <mutex>
#include <string>
#include <utility>

namespace specula::gpu {

static_assert(sizeof(Ray) == sizeof(GpuRay) && offsetof(Ray, direction) == offsetof(GpuRay, direction) &&
              offsetof(Ray, tfar) == offsetof(GpuRay, tfar));
static_assert(kNoInstance == kNoIndex);

namespace {

/// trace_rays.comp's push constants.
struct TracePush {
  std::uint32_t ray_count;
  std::uint32_t budget;
  std::uint32_t any_hit;
  std::uint32_t resume;
  std::uint32_t stack_stride;
};

constexpr std::uint32_t kTraceGroup = 64; // trace_rays.comp's local_size_x
/// Rays per round of dispatches: bounds the saved state (a stack of up to kTraceStackSize entries
/// per ray) below lavapipe's 128 MiB storage buffer range.
constexpr std::size_t kChunkRays = std::size_t(1) << 16;
/// A batch that still has rays to resume after this many dispatches is not making progress.
constexpr std::uint32_t kMaxDispatches = 1u << 20;

} // namespace

/// trace_rays.comp and the buffers of its batches, kept between calls (grown, never shrunk).
struct VulkanTracer::Kernels {
  explicit Kernels(Context& context) : cmd(context) {}
  Pipeline trace;
  Pipeline trace_static; ///< trace without the top level's code, for scenes without one
  Commands cmd; ///< recorded and submitted again for every dispatch (submit resets it)
  std::mutex mutex;
  std::size_t capacity = 0;      ///< rays the batch buffers hold
  std::uint32_t stack_stride = 0; ///< saved stack entries per ray they were sized for
  // The counters live in device memory (a kernel's atomics on host memory would cross the
  // bus); each dispatch's commands copy them into counters_host.
  Buffer rays, hits, occluded, states, stacks, counters, counters_host;
  Buffer status[2];
  std::vector<GpuHit> hit_host;
  std::vector<std::uint32_t> word_host;
  std::vector<Ray> camera_rays;
  std::vector<Hit> camera_hits;

  void reserve(Context& context, std::size_t n, std::uint32_t stride) {
    if (n <= capacity && stride <= stack_stride) return;
    capacity = std::max(n, capacity);
    stack_stride = std::max(stride, stack_stride);
    rays = context.make_buffer(capacity * sizeof(GpuRay));
    hits = context.make_buffer(capacity * sizeof(GpuHit));
    occluded = context.make_buffer(capacity * sizeof(std::uint32_t));
    states = context.make_buffer(capacity * sizeof(GpuTraceState));
    stacks = context.make_buffer(capacity * stack_stride * 2 * sizeof(std::uint32_t));
    for (Buffer& s : status) s = context.make_buffer(capacity * sizeof(std::uint32_t));
    if (!counters.valid()) counters = context.make_buffer(sizeof(TraceCounters));
    if (!counters_host.valid())
      counters_host = context.make_buffer(sizeof(TraceCounters), MemoryKind::host);
  }
};

VulkanTracer::VulkanTracer(std::uint32_t packet_width, VulkanOptions options)
    : packet_width_(packet_width), options_(std::move(options)),
      name_(options_.structure == GpuStructure::grid ? "vulkan-grid" : "vulkan") {
  context_ = options_.device ? options_.device
                             : std::shared_ptr<Context>(Context::create(options_.context));
  scene_ = std::make_unique<GpuScene>(*context_, options_.structure, options_.grid_density);
  kernels_ = std::make_unique<Kernels>(*context_);
  PipelineDesc desc;
  desc.spirv = shader_spirv("trace_rays");
  desc.storage_buffers = kSceneBindings + 8;
  desc.push_constant_bytes = sizeof(TracePush);
  desc.specialization = {options_.count_tests ? 1u : 0u,
                         options_.structure == GpuStructure::grid ? 1u : 0u, 1u};
  desc.debug_name = "trace_rays";
  desc.texel_buffers = GpuScene::texel_bindings();
  desc.texel_buffers.push_back({kSceneBindings, VK_FORMAT_R32G32B32A32_UINT}); // the rays
  kernels_->trace = context_->make_pipeline(desc);
  desc.specialization[2] = 0u;
  kernels_->trace_static = context_->make_pipeline(desc);
  renderer_ = std::make_unique<DeviceRenderer>(*context_, *scene_, options_.execution,
                                               options_.primary);
}

VulkanTracer::~VulkanTracer() = default;

// Device frames run on the caller's thread alone, as render_frame_on_device does (the mutex
// guards the CPU integrators' batches).
void VulkanTracer::set_keep_frames_on_device(bool keep) {
  renderer_->set_keep_frames_on_device(keep);
}

const DeviceFrame* VulkanTracer::device_frame() const { return renderer_->device_frame(); }

void VulkanTracer::read_back_frame(Framebuffer& out) const { renderer_->read_back(out); }

const TracerUpdateStats& VulkanTracer::update(const SceneLayer& layer) { return scene_->update(layer); }
const TracerUpdateStats& VulkanTracer::last_update() const { return scene_->last_update(); }

void VulkanTracer::trace_locked(std::span<const Ray> rays, Hit* hits,
                                std::uint8_t* occluded) const {
  Kernels& k = *kernels_;
  GpuTraceCounters total;
  const std::uint32_t stride = scene_->stack_depth();
  const std::uint32_t budget = std::max(options_.traversal_budget, 1u);
  for (std::size_t first = 0; first < rays.size(); first += kChunkRays) {
    const std::size_t n = std::min(kChunkRays, rays.size() - first);
    k.reserve(*context_, n, stride);
    k.rays.upload(rays.data() + first, n * sizeof(Ray));
    Commands& cmd = k.cmd;
    int in = 0;
    for (std::uint32_t dispatch = 0;; ++dispatch) {
      if (dispatch == kMaxDispatches)
        throw Error("vulkan: rays still unfinished after " + std::to_string(dispatch) +
                    " dispatches of trace_rays");
      const int out = 1 - in;
      cmd.fill(k.counters, 0u);
      cmd.fill(k.status[out], kRayPending);
      cmd.barrier();
      const TracePush push{std::uint32_t(n), budget, occluded != nullptr ? 1u : 0u,
                           dispatch > 0 ? 1u : 0u, stride};
      std::array<const Buffer*, kSceneBindings + 8> buffers{};
      const std::span<const Buffer* const> scene = scene_->bindings();
      std::copy(scene.begin(), scene.end(), buffers.begin());
      const Buffer* own[] = {&k.rays,      &k.hits,   &k.occluded, &k.status[in],
                             &k.status[out], &k.states, &k.stacks,   &k.counters};
      std::copy(std::begin(own), std::end(own), buffers.begin() + kSceneBindings);
      const std::uint32_t t0 = cmd.timestamp();
      cmd.dispatch(scene_->has_top_level() ? k.trace : k.trace_static,
                   std::span<const Buffer* const>(buffers), &push,
                   std::uint32_t((n + kTraceGroup - 1) / kTraceGroup));
      const std::uint32_t t1 = cmd.timestamp();
      cmd.barrier();
      cmd.copy(k.counters, k.counters_host, sizeof(TraceCounters));
      cmd.host_barrier();
      cmd.submit();
      total.gpu_ms += cmd.elapsed_ms(t0, t1);
      ++total.dispatches;
      TraceCounters c;
      std::memcpy(&c, k.counters_host.mapped(), sizeof c);
      total.resumed += c.budget;
      total.cut += c.cut;
      for (std::uint32_t s = 0; s < kStepSlots; ++s) total.steps += c.steps[s * kStepSlotStride];
      total.tests += c.tests;
      in = out;
      if (c.budget == 0) break;
    }
    // Rays the last dispatch left pending were cut off there.
    k.word_host.resize(n);
    k.status[in].download(std::span<std::uint32_t>(k.word_host));
    total.cut += std::uint64_t(std::count(k.word_host.begin(), k.word_host.end(), kRayPending));
    if (occluded != nullptr) {
      k.occluded.download(std::span<std::uint32_t>(k.word_host));
      for (std::size_t i = 0; i < n; ++i) occluded[first + i] = std::uint8_t(k.word_host[i]);
    } else {
      k.hit_host.resize(n);
      k.hits.download(std::span<GpuHit>(k.hit_host));
      for (std::size_t i = 0; i < n; ++i) {
        const GpuHit& g = k.hit_host[i];
        Hit& h = hits[first + i];
        h.t = g.t;
        h.instance = g.instance;
        h.primitive = g.primitive;
        h.uv = vec2(g.u, g.v);
        h.object_normal = vec3(g.ng_x, g.ng_y, g.ng_z);
      }
    }
    total.rays += n;
  }
  counters_ = total;
  if (total.cut != 0)
    throw Error("vulkan: the driver cut off " + std::to_string(total.cut) +
                " rays' traversal (a loop ran past the device's iteration limit; lower "
                "VulkanOptions::traversal_budget)");
}

void VulkanTracer::intersect(std::span<const Ray> rays, std::span<Hit> hits) const {
  SPECULA_ASSERT(hits.size() == rays.size());
  if (rays.empty()) return;
  const std::lock_guard lock(kernels_->mutex);
  trace_locked(rays, hits.data(), nullptr);
}

void VulkanTracer::occluded(std::span<const Ray> rays, std::span<std::uint8_t> occluded) const {
  SPECULA_ASSERT(occluded.size() == rays.size());
  if (rays.empty()) return;
  const std::lock_guard lock(kernels_->mutex);
  trace_locked(rays, nullptr, occluded.data());
}

void VulkanTracer::intersect_camera(const CameraRays& camera, const PacketTile& tile,
                                    PrimaryHits& hits) const {
  const std::size_t n = tile.pixel_count();
  hits.resize(n);
  if (n == 0) return;
  // The directions in the tile's trace order, as every backend generates them.
  camera.tile_directions(tile, hits.dir_x.data(), hits.dir_y.data(), hits.dir_z.data());
  const std::lock_guard lock(kernels_->mutex);
  Kernels& k = *kernels_;
  k.camera_rays.resize(n);
  k.camera_hits.resize(n);
  for (std::size_t i = 0; i < n; ++i)
    k.camera_rays[i] = Ray{camera.origin, 0.0f, hits.direction(i),
                           std::numeric_limits<float>::infinity()};
  trace_locked(k.camera_rays, k.camera_hits.data(), nullptr);
  for (std::size_t i = 0; i < n; ++i) hits.set(i, k.camera_hits[i]);
}

bool VulkanTracer::render_frame_on_device(const SceneLayer& layer, const Camera& camera,
                                          const TraceSettings& settings, Framebuffer& out,
                                          RadianceHook* hook, GuideBuffers* guides,
                                          FrameStats& stats) const {
  if (!options_.device_frames || !renderer_->supports(settings, hook, guides != nullptr))
    return false;
  renderer_->render(layer, camera, settings, out, stats, counters_, hook, guides);
  // The frame's own device counters, for the stats file (frames[].gpu).
  stats.gpu = GpuFrameStats{true,
                            counters_.rays,
                            counters_.resumed,
                            counters_.cut,
                            counters_.dispatches,
                            counters_.gpu_ms,
                            counters_.stage_ms,
                            counters_.submits};
  return true;
}

void VulkanTracer::set_packet_width(std::uint32_t width) { packet_width_ = width; }

} // namespace specula::gpu
