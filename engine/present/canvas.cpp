#include "specula/present/canvas.h"

#include "specula/gpu/shaders.h"
#include "specula/image/srgb.h"

#include <backends/imgui_impl_vulkan.h>
#include <imgui.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <stdexcept>
#include <utility>
#include <vector>

namespace specula::present {

Letterbox letterbox(std::uint64_t fw, std::uint64_t fh, std::uint32_t width, std::uint32_t height) {
  Letterbox l;
  // Scale to fit, aspect kept: the drawn rectangle is dw × dh, centred; the rest stays black.
  if (fw > 0 && fh > 0 && width > 0 && height > 0) {
    if (std::uint64_t(width) * fh <= std::uint64_t(height) * fw) { // width-bound
      l.dw = width;
      l.dh = std::clamp<std::uint64_t>((fh * width + fw / 2) / fw, 1, height);
    } else {
      l.dh = height;
      l.dw = std::clamp<std::uint64_t>((fw * height + fh / 2) / fh, 1, width);
    }
  }
  l.ox = (width - l.dw) / 2;
  l.oy = (height - l.dh) / 2;
  // A frame drawn larger than it is (dynamic resolution) is scaled up bilinearly, in linear
  // colour; one drawn at its size or smaller takes the source pixel under each destination
  // pixel's centre (nearest neighbour, in integers: at the same size, the frame itself).
  l.bilinear = l.dw >= fw && l.dh >= fh && (l.dw > fw || l.dh > fh);
  return l;
}

void encode_srgb8_into(const Framebuffer& frame, std::uint32_t width, std::uint32_t height,
                       std::span<std::uint8_t> out, bool bgra) {
  const std::uint64_t fw = frame.width(), fh = frame.height();
  const Letterbox box = letterbox(fw, fh, width, height);
  // Plain copies: the row lambda below captures them (clang 15 cannot capture bindings).
  const std::uint64_t ox = box.ox, oy = box.oy, dw = box.dw, dh = box.dh;
  const bool bilinear = box.bilinear;
  const auto pixels = frame.pixels();
  const std::size_t r = bgra ? 2 : 0, b = bgra ? 0 : 2;
  // Each drawn column's source column (or taps), once per frame rather than a division per pixel.
  std::vector<LinearTaps> columns;
  std::vector<std::uint32_t> nearest_columns;
  if (bilinear) {
    columns.resize(dw);
    for (std::uint64_t x = 0; x < dw; ++x) columns[x] = linear_source(x, dw, fw);
  } else {
    nearest_columns.resize(dw);
    for (std::uint64_t x = 0; x < dw; ++x)
      nearest_columns[x] = std::uint32_t(nearest_source(x, dw, fw));
  }
  const Srgb8Encoder& encode = Srgb8Encoder::get();
  const auto black = [](std::uint8_t* p, std::uint64_t count) {
    for (std::uint64_t i = 0; i < count; ++i, p += 4) {
      p[0] = p[1] = p[2] = 0;
      p[3] = 255;
    }
  };
  tbb::parallel_for(tbb::blocked_range<std::uint32_t>(0, height), [&](const auto& rows) {
    for (std::uint32_t y = rows.begin(); y != rows.end(); ++y) {
      std::uint8_t* row = out.data() + std::size_t(y) * width * 4;
      if (y < oy || y >= oy + dh) {
        black(row, width);
        continue;
      }
      black(row, ox);
      black(row + (ox + dw) * 4, width - ox - dw);
      std::uint8_t* p = row + ox * 4;
      const auto put = [&](const vec3& c) {
        p[r] = encode(c.r);
        p[1] = encode(c.g);
        p[b] = encode(c.b);
        p[3] = 255;
        p += 4;
      };
      if (bilinear) {
        const LinearTaps ty = linear_source(y - oy, dh, fh);
        const vec3* lo = &pixels[std::size_t(ty.lo) * fw];
        const vec3* hi = &pixels[std::size_t(ty.hi) * fw];
        for (const LinearTaps& tx : columns)
          put(lerp_taps(lerp_taps(lo[tx.lo], lo[tx.hi], tx.weight),
                        lerp_taps(hi[tx.lo], hi[tx.hi], tx.weight), ty.weight));
      } else {
        const vec3* source = &pixels[std::size_t(nearest_source(y - oy, dh, fh) * fw)];
        for (const std::uint32_t sx : nearest_columns) put(source[sx]);
      }
    }
  });
}

Rgba8Image encode_srgb8(const Framebuffer& frame, std::uint32_t width, std::uint32_t height) {
  Rgba8Image image;
  image.width = width;
  image.height = height;
  image.rgba.resize(std::size_t(width) * height * 4);
  encode_srgb8_into(frame, width, height, image.rgba);
  return image;
}

namespace {

void check_imgui(VkResult r) { gpu::check(r, "Dear ImGui's Vulkan backend"); }

} // namespace

Canvas::Canvas(gpu::Context& context, bool ui, VkFormat format)
    : context_(context), ui_(ui), format_(format) {
  if (format != VK_FORMAT_R8G8B8A8_UNORM && format != VK_FORMAT_B8G8R8A8_UNORM)
    throw std::invalid_argument("a canvas is RGBA8 or BGRA8 UNORM");
  // The frame is copied in first (TRANSFER_DST), the UI drawn over it (LOAD), and the result read
  // by a blit or a readback (TRANSFER_SRC).
  VkAttachmentDescription colour{};
  colour.format = format_;
  colour.samples = VK_SAMPLE_COUNT_1_BIT;
  colour.loadOp = VK_ATTACHMENT_LOAD_OP_LOAD;
  colour.storeOp = VK_ATTACHMENT_STORE_OP_STORE;
  colour.stencilLoadOp = VK_ATTACHMENT_LOAD_OP_DONT_CARE;
  colour.stencilStoreOp = VK_ATTACHMENT_STORE_OP_DONT_CARE;
  colour.initialLayout = VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL;
  colour.finalLayout = VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL;
  VkAttachmentReference ref{0, VK_IMAGE_LAYOUT_COLOR_ATTACHMENT_OPTIMAL};
  VkSubpassDescription subpass{};
  subpass.pipelineBindPoint = VK_PIPELINE_BIND_POINT_GRAPHICS;
  subpass.colorAttachmentCount = 1;
  subpass.pColorAttachments = &ref;
  VkSubpassDependency deps[2]{};
  deps[0].srcSubpass = VK_SUBPASS_EXTERNAL;
  deps[0].dstSubpass = 0;
  deps[0].srcStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT;
  deps[0].srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  deps[0].dstStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  deps[0].dstAccessMask = VK_ACCESS_COLOR_ATTACHMENT_READ_BIT | VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  deps[1].srcSubpass = 0;
  deps[1].dstSubpass = VK_SUBPASS_EXTERNAL;
  deps[1].srcStageMask = VK_PIPELINE_STAGE_COLOR_ATTACHMENT_OUTPUT_BIT;
  deps[1].srcAccessMask = VK_ACCESS_COLOR_ATTACHMENT_WRITE_BIT;
  deps[1].dstStageMask = VK_PIPELINE_STAGE_TRANSFER_BIT;
  deps[1].dstAccessMask = VK_ACCESS_TRANSFER_READ_BIT;
  VkRenderPassCreateInfo rpi{VK_STRUCTURE_TYPE_RENDER_PASS_CREATE_INFO};
  rpi.attachmentCount = 1;
  rpi.pAttachments = &colour;
  rpi.subpassCount = 1;
  rpi.pSubpasses = &subpass;
  rpi.dependencyCount = 2;
  rpi.pDependencies = deps;
  gpu::check(vkCreateRenderPass(context_.device(), &rpi, nullptr, &render_pass_), "vkCreateRenderPass");
  if (!ui_) return;

  try {
    // The backend needs one combined image sampler (the font atlas); a few spare for textures
    // an application registers.
    VkDescriptorPoolSize size{VK_DESCRIPTOR_TYPE_COMBINED_IMAGE_SAMPLER, 16};
    VkDescriptorPoolCreateInfo dpi{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
    dpi.flags = VK_DESCRIPTOR_POOL_CREATE_FREE_DESCRIPTOR_SET_BIT;
    dpi.maxSets = 16;
    dpi.poolSizeCount = 1;
    dpi.pPoolSizes = &size;
    gpu::check(vkCreateDescriptorPool(context_.device(), &dpi, nullptr, &ui_pool_),
               "vkCreateDescriptorPool");
    ImGui_ImplVulkan_InitInfo info{};
    info.Instance = context_.instance();
    info.PhysicalDevice = context_.physical_device();
    info.Device = context_.device();
    info.QueueFamily = context_.queue_family();
    info.Queue = context_.queue();
    info.DescriptorPool = ui_pool_;
    // One frame in flight (present() waits for the previous frame), so two vertex buffer sets
    // are enough.
    info.MinImageCount = 2;
    info.ImageCount = 2;
    info.MSAASamples = VK_SAMPLE_COUNT_1_BIT;
    info.CheckVkResultFn = &check_imgui;
    if (!ImGui_ImplVulkan_Init(&info, render_pass_))
      throw gpu::GpuError("ImGui_ImplVulkan_Init", VK_ERROR_INITIALIZATION_FAILED);
    context_.run_now([](VkCommandBuffer cmd) { ImGui_ImplVulkan_CreateFontsTexture(cmd); });
    ImGui_ImplVulkan_DestroyFontUploadObjects();
  } catch (...) {
    if (ui_pool_ != VK_NULL_HANDLE) vkDestroyDescriptorPool(context_.device(), ui_pool_, nullptr);
    vkDestroyRenderPass(context_.device(), render_pass_, nullptr);
    throw;
  }
}

Canvas::~Canvas() {
  try {
    context_.wait_idle();
  } catch (const gpu::GpuError&) { // a lost device: nothing runs any more
  }
  encoder_.reset();
  if (ui_) ImGui_ImplVulkan_Shutdown();
  if (framebuffer_ != VK_NULL_HANDLE) vkDestroyFramebuffer(context_.device(), framebuffer_, nullptr);
  if (ui_pool_ != VK_NULL_HANDLE) vkDestroyDescriptorPool(context_.device(), ui_pool_, nullptr);
  vkDestroyRenderPass(context_.device(), render_pass_, nullptr);
}

void Canvas::resize(std::uint32_t width, std::uint32_t height) {
  if (width == width_ && height == height_ && image_.valid()) return;
  if (framebuffer_ != VK_NULL_HANDLE) {
    vkDestroyFramebuffer(context_.device(), framebuffer_, nullptr);
    framebuffer_ = VK_NULL_HANDLE;
  }
  width_ = width;
  height_ = height;
  image_ = context_.make_image(width, height, format_,
                               VK_IMAGE_USAGE_COLOR_ATTACHMENT_BIT | VK_IMAGE_USAGE_TRANSFER_DST_BIT |
                                   VK_IMAGE_USAGE_TRANSFER_SRC_BIT);
  const VkDeviceSize bytes = VkDeviceSize(width) * height * 4;
  staging_ = context_.make_buffer(bytes, gpu::MemoryKind::host);
  readback_ = context_.make_buffer(bytes, gpu::MemoryKind::host);
  const VkImageView view = image_.view();
  VkFramebufferCreateInfo fci{VK_STRUCTURE_TYPE_FRAMEBUFFER_CREATE_INFO};
  fci.renderPass = render_pass_;
  fci.attachmentCount = 1;
  fci.pAttachments = &view;
  fci.width = width;
  fci.height = height;
  fci.layers = 1;
  gpu::check(vkCreateFramebuffer(context_.device(), &fci, nullptr, &framebuffer_),
             "vkCreateFramebuffer");
}

void Canvas::record(VkCommandBuffer cmd, const Framebuffer& frame, ImDrawData* ui) {
  encode_srgb8_into(frame, width_, height_,
                    {static_cast<std::uint8_t*>(staging_.mapped()), std::size_t(width_) * height_ * 4},
                    format_ == VK_FORMAT_B8G8R8A8_UNORM);
  record_pixels(cmd, staging_, ui);
}

/// present_encode.comp and what it reads besides the frame: the encoder's thresholds, the
/// letterbox's taps (host-visible, rewritten per frame), the encoded pixels (device-local).
struct Canvas::DeviceEncoder {
  /// present_encode.comp's push constants.
  struct Push {
    std::uint32_t width, height, ox, oy, dw, dh, src_width, bgra;
  };
  /// One column's or row's source samples (LinearTaps, padded to 16 bytes).
  struct Tap {
    std::uint32_t lo, hi;
    float weight;
    std::uint32_t unused;
  };
  gpu::Pipeline pipeline;
  VkDescriptorPool pool = VK_NULL_HANDLE;
  VkDescriptorSet set = VK_NULL_HANDLE;
  gpu::Buffer thresholds, taps, pixels;
  VkDevice device = VK_NULL_HANDLE;

  explicit DeviceEncoder(gpu::Context& context) : device(context.device()) {
    gpu::PipelineDesc desc;
    desc.spirv = gpu::shader_spirv("present_encode");
    desc.storage_buffers = 4;
    desc.push_constant_bytes = sizeof(Push);
    desc.debug_name = "present_encode";
    pipeline = context.make_pipeline(desc);
    const VkDescriptorPoolSize size{VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 4};
    VkDescriptorPoolCreateInfo dpi{VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO};
    dpi.maxSets = 1;
    dpi.poolSizeCount = 1;
    dpi.pPoolSizes = &size;
    gpu::check(vkCreateDescriptorPool(device, &dpi, nullptr, &pool), "vkCreateDescriptorPool");
    const VkDescriptorSetLayout layout = pipeline.set_layout();
    VkDescriptorSetAllocateInfo ai{VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO};
    ai.descriptorPool = pool;
    ai.descriptorSetCount = 1;
    ai.pSetLayouts = &layout;
    gpu::check(vkAllocateDescriptorSets(device, &ai, &set), "vkAllocateDescriptorSets");
    // threshold[k] is the least value that encodes to k; 0 and 2 bound the search.
    std::array<float, 257> t{};
    const Srgb8Encoder& encoder = Srgb8Encoder::get();
    for (std::uint32_t k = 1; k < 256; ++k) t[k] = encoder.threshold(k);
    t[256] = 2.0f;
    thresholds = context.make_buffer(sizeof t, gpu::MemoryKind::host);
    thresholds.upload(t.data(), sizeof t);
  }
  ~DeviceEncoder() { vkDestroyDescriptorPool(device, pool, nullptr); }
  DeviceEncoder(const DeviceEncoder&) = delete;
  DeviceEncoder& operator=(const DeviceEncoder&) = delete;
};

void Canvas::record(VkCommandBuffer cmd, const gpu::DeviceFrame& frame, ImDrawData* ui) {
  if (frame.context != &context_ || frame.radiance == nullptr)
    throw std::invalid_argument("a device frame is drawn by a canvas on its own device");
  if (frame.radiance->size() < VkDeviceSize(frame.width) * frame.height * 16)
    throw std::invalid_argument("a device frame's buffer is smaller than its size");
  if (!encoder_) encoder_ = std::make_unique<DeviceEncoder>(context_);
  DeviceEncoder& e = *encoder_;
  const VkDeviceSize bytes = VkDeviceSize(width_) * height_ * 4;
  gpu::ensure_size(context_, e.pixels, bytes);

  const Letterbox box = letterbox(frame.width, frame.height, width_, height_);
  gpu::ensure_size(context_, e.taps, (box.dw + box.dh) * sizeof(DeviceEncoder::Tap),
                   gpu::MemoryKind::host);
  auto* tap = static_cast<DeviceEncoder::Tap*>(e.taps.mapped());
  const auto fill = [&](std::uint64_t drawn, std::uint64_t source) {
    for (std::uint64_t i = 0; i < drawn; ++i, ++tap) {
      if (box.bilinear) {
        const LinearTaps t = linear_source(i, drawn, source);
        *tap = {t.lo, t.hi, t.weight, 0};
      } else {
        const auto n = std::uint32_t(nearest_source(i, drawn, source));
        *tap = {n, n, 0.0f, 0};
      }
    }
  };
  fill(box.dw, frame.width);
  fill(box.dh, frame.height);

  // The frame's kernels (an earlier submission) wrote the radiance; the previous frame's copy
  // read the pixels: both finish before the encoding.
  VkMemoryBarrier mb{VK_STRUCTURE_TYPE_MEMORY_BARRIER};
  mb.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT;
  mb.dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT;
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT,
                       VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, 1, &mb, 0, nullptr, 0, nullptr);
  const DeviceEncoder::Push push{width_,
                                 height_,
                                 std::uint32_t(box.ox),
                                 std::uint32_t(box.oy),
                                 std::uint32_t(box.dw),
                                 std::uint32_t(box.dh),
                                 frame.width,
                                 format_ == VK_FORMAT_B8G8R8A8_UNORM ? 1u : 0u};
  const gpu::Buffer* buffers[] = {frame.radiance, &e.taps, &e.thresholds, &e.pixels};
  gpu::record_dispatch(cmd, e.set, e.pipeline, buffers, &push, (width_ + 7) / 8, (height_ + 7) / 8);
  mb.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
  mb.dstAccessMask = VK_ACCESS_TRANSFER_READ_BIT;
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0,
                       1, &mb, 0, nullptr, 0, nullptr);
  record_pixels(cmd, e.pixels, ui);
}

void Canvas::record_pixels(VkCommandBuffer cmd, const gpu::Buffer& pixels, ImDrawData* ui) {
  // The previous contents are replaced whole; the stages that last read the image (a blit or a
  // readback, both transfers) finish before the copy writes it.
  gpu::image_barrier(cmd, image_.handle(), VK_IMAGE_ASPECT_COLOR_BIT, VK_IMAGE_LAYOUT_UNDEFINED,
                     VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, VK_PIPELINE_STAGE_TRANSFER_BIT, 0,
                     VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT);
  VkBufferImageCopy region{};
  region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  region.imageExtent = {width_, height_, 1};
  vkCmdCopyBufferToImage(cmd, pixels.handle(), image_.handle(),
                         VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &region);
  if (ui_ && ui != nullptr && ui->CmdListsCount > 0) {
    VkRenderPassBeginInfo rbi{VK_STRUCTURE_TYPE_RENDER_PASS_BEGIN_INFO};
    rbi.renderPass = render_pass_;
    rbi.framebuffer = framebuffer_;
    rbi.renderArea.extent = {width_, height_};
    vkCmdBeginRenderPass(cmd, &rbi, VK_SUBPASS_CONTENTS_INLINE);
    ImGui_ImplVulkan_RenderDrawData(ui, cmd);
    vkCmdEndRenderPass(cmd);
  } else {
    // No UI: skip the pass, whose attachment load and store cost a software rasteriser a copy.
    gpu::image_barrier(cmd, image_.handle(), VK_IMAGE_ASPECT_COLOR_BIT,
                       VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL,
                       VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                       VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT);
  }
}

void Canvas::record_readback(VkCommandBuffer cmd) {
  VkBufferImageCopy region{};
  region.imageSubresource = {VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
  region.imageExtent = {width_, height_, 1};
  vkCmdCopyImageToBuffer(cmd, image_.handle(), VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL,
                         readback_.handle(), 1, &region);
  VkBufferMemoryBarrier b{VK_STRUCTURE_TYPE_BUFFER_MEMORY_BARRIER};
  b.srcAccessMask = VK_ACCESS_TRANSFER_WRITE_BIT;
  b.dstAccessMask = VK_ACCESS_HOST_READ_BIT;
  b.srcQueueFamilyIndex = b.dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED;
  b.buffer = readback_.handle();
  b.size = VK_WHOLE_SIZE;
  vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 0,
                       nullptr, 1, &b, 0, nullptr);
}

Rgba8Image Canvas::readback() const {
  Rgba8Image out;
  out.width = width_;
  out.height = height_;
  const auto* data = static_cast<const std::uint8_t*>(readback_.mapped());
  out.rgba.assign(data, data + std::size_t(width_) * height_ * 4);
  if (format_ == VK_FORMAT_B8G8R8A8_UNORM)
    for (std::size_t i = 0; i < out.rgba.size(); i += 4) std::swap(out.rgba[i], out.rgba[i + 2]);
  return out;
}

} // namespace specula::present
