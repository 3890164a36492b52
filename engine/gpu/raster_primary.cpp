#include "specula/gpu/raster_primary.h"

#include "specula/gpu/shaders.h"
#include "specula/render/scene_layer.h"
#include "specula/shared/scene_layout.h"
#include "specula/trace/camera_rays.h"

#include <algorithm>

namespace specula::gpu {

RasterPrimary::RasterPrimary(Context& context, const GpuScene& scene)
    : context_(context), scene_(scene) {
  GraphicsPipelineDesc desc;
  desc.vertex_spirv = shader_spirv("gbuffer_vert");
  desc.fragment_spirv = shader_spirv("gbuffer_frag");
  desc.storage_buffers = 4; // positions, triangles, meshes, instances
  desc.push_constant_bytes = sizeof(Push);
  desc.colour_format = VK_FORMAT_R32G32_UINT;
  desc.depth_format = VK_FORMAT_D32_SFLOAT;
  desc.depth_compare = VK_COMPARE_OP_GREATER; // reversed depth: nearer is larger
  desc.debug_name = "gbuffer (hybrid mode's raster pass)";
  pipeline_ = context.make_graphics_pipeline(desc);
}

void RasterPrimary::prepare(const SceneLayer& layer, const CameraRays& rays, std::uint32_t width,
                            std::uint32_t height) {
  const SceneTables& tables = layer.tables();
  const auto draw = [&](std::uint32_t slot) {
    const GpuInstance& inst = tables.instances[slot];
    if (inst.mesh == kNoIndex) return;
    draws_.push_back({3 * tables.meshes[inst.mesh].triangle_count, slot});
  };
  draws_.clear();
  std::vector<std::uint32_t> boxes(std::max<std::size_t>(1, tables.instances.size()), kNoIndex);
  for (const std::uint32_t slot : scene_.native().static_slots()) draw(slot);
  const std::span<const GpuTopEntry> top = scene_.top_entries();
  for (std::uint32_t box = 0; box < top.size(); ++box) {
    boxes[top[box].slot] = box;
    draw(top[box].slot);
  }
  ensure_size(context_, slot_boxes_, boxes.size() * 4);
  slot_boxes_.upload(boxes.data(), boxes.size() * 4);

  if (!colour_.valid() || colour_.width() != width || colour_.height() != height) {
    colour_ =
        context_.make_image(width, height, VK_FORMAT_R32G32_UINT,
                            VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT);
    depth_ = context_.make_image(width, height, VK_FORMAT_D32_SFLOAT,
                                 VK_IMAGE_USAGE_DEPTH_STENCIL_ATTACHMENT_BIT);
    visibility_ = context_.make_buffer(VkDeviceSize(width) * height * 8);
  }
  // The camera's basis is orthogonal (CameraRays): dividing right and up by their squared
  // lengths makes d·right / d·forward the image-plane coordinate sx of CameraRays::ray.
  const vec3 right = rays.right / glm::dot(rays.right, rays.right);
  const vec3 up = rays.up / glm::dot(rays.up, rays.up);
  push_ = Push{{rays.origin.x, rays.origin.y, rays.origin.z, kNear},
               {right.x, right.y, right.z, 0.0f},
               {up.x, up.y, up.z, 0.0f},
               {rays.forward.x, rays.forward.y, rays.forward.z, 0.0f}};
}

void RasterPrimary::record(Commands& cmd) const {
  const std::span<const Buffer* const> scene = scene_.bindings();
  VkClearColorValue clear{};
  clear.uint32[0] = kNoIndex;
  clear.uint32[1] = 0;
  cmd.begin_rendering(colour_, depth_, clear, 0.0f);
  cmd.draw(pipeline_, scene.subspan(0, 4), &push_, draws_);
  cmd.end_rendering();
  cmd.copy(colour_, visibility_);
}

} // namespace specula::gpu
