#include "specula/gpu/vulkan_tracer.h"

#include "specula/core/error.h"
#include "specula/gpu/device_renderer.h"
#include "specula/render/scene_layer.h"
#include "specula/trace/render_frame.h"

namespace specula::gpu {

static_assert(sizeof(Ray) == sizeof(GpuRay) && offsetof(Ray, direction) == offsetof(GpuRay, direction) &&
              offsetof(Ray, tfar) == offsetof(GpuRay, tfar));

// GROUNDWORK STUB: the traversal kernels, their batches and resumption land here.
struct VulkanTracer::Kernels {};

VulkanTracer::VulkanTracer(std::uint32_t packet_width, VulkanOptions options)
    : packet_width_(packet_width), options_(std::move(options)),
      name_(options_.structure == GpuStructure::grid ? "vulkan-grid" : "vulkan") {
  context_ = Context::create(options_.context);
  scene_ = std::make_unique<GpuScene>(*context_, options_.structure);
  kernels_ = std::make_unique<Kernels>();
  renderer_ = std::make_unique<DeviceRenderer>(*context_, *scene_, options_.execution);
}

VulkanTracer::~VulkanTracer() = default;

const TracerUpdateStats& VulkanTracer::update(const SceneLayer& layer) { return scene_->update(layer); }
const TracerUpdateStats& VulkanTracer::last_update() const { return scene_->last_update(); }

void VulkanTracer::intersect(std::span<const Ray>, std::span<Hit>) const {
  throw Error("vulkan", "intersect is not implemented yet");
}
void VulkanTracer::occluded(std::span<const Ray>, std::span<std::uint8_t>) const {
  throw Error("vulkan", "occluded is not implemented yet");
}
void VulkanTracer::intersect_camera(const CameraRays&, const PacketTile&, PrimaryHits&) const {
  throw Error("vulkan", "intersect_camera is not implemented yet");
}

bool VulkanTracer::render_frame_on_device(const SceneLayer& layer, const Camera& camera,
                                          const TraceSettings& settings, Framebuffer& out,
                                          RadianceHook* hook, GuideBuffers* guides,
                                          FrameStats& stats) const {
  if (!options_.device_frames || !renderer_->supports(settings, hook != nullptr, guides != nullptr))
    return false;
  renderer_->render(layer, camera, settings, out, stats, counters_);
  return true;
}

void VulkanTracer::set_packet_width(std::uint32_t width) { packet_width_ = width; }

} // namespace specula::gpu
