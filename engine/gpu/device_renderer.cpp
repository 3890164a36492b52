#include "specula/gpu/device_renderer.h"

#include "specula/core/error.h"
#include "specula/gpu/vulkan_tracer.h"
#include "specula/trace/render_frame.h"

namespace specula::gpu {

DeviceRenderer::DeviceRenderer(Context& context, const GpuScene& scene, Execution execution)
    : context_(context), scene_(scene), execution_(execution) {}

DeviceRenderer::~DeviceRenderer() = default;

bool DeviceRenderer::supports(const TraceSettings&, bool, bool) const { return false; }

void DeviceRenderer::render(const SceneLayer&, const Camera&, const TraceSettings&, Framebuffer&,
                            FrameStats&, GpuTraceCounters&) {
  throw Error("vulkan", "device frames are not implemented yet");
}

} // namespace specula::gpu
