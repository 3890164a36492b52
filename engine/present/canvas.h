#pragma once
/// \file
/// What Window and Offscreen share: an R8G8B8A8_UNORM (or B8G8R8A8_UNORM, a swapchain's order) image the frame is uploaded into (already
/// sRGB-encoded on the CPU, letterboxed to the image's size) with Dear ImGui's draw data rendered
/// over it in a render pass (Dear ImGui 1.86's Vulkan backend needs a VkRenderPass). A window then
/// blits the image into its swapchain; the image persists, so read_back() reads it.

#include "specula/gpu/device_renderer.h"
#include "specula/gpu/vk_context.h"
#include "specula/present/window.h"

#include <memory>
#include <span>

namespace specula::present {

/// encode_srgb8 into `out` (width * height * 4 bytes), rows in parallel; `bgra`: blue first.
void encode_srgb8_into(const Framebuffer& frame, std::uint32_t width, std::uint32_t height,
                       std::span<std::uint8_t> out, bool bgra = false);

/// Where a frame_width × frame_height frame is drawn on a width × height target: scaled to fit
/// with its aspect kept, centred (dw × dh at ox, oy; black bars around), bilinearly when drawn
/// larger than it is, else nearest neighbour. The CPU and the device encodings both follow it.
struct Letterbox {
  std::uint64_t ox = 0, oy = 0, dw = 0, dh = 0;
  bool bilinear = false;
};
[[nodiscard]] Letterbox letterbox(std::uint64_t frame_width, std::uint64_t frame_height,
                                  std::uint32_t width, std::uint32_t height);

class Canvas {
public:
  /// With `ui`, initialises Dear ImGui's Vulkan backend on the current ImGui context. `format`:
  /// VK_FORMAT_R8G8B8A8_UNORM or VK_FORMAT_B8G8R8A8_UNORM (a window's swapchain format, so the
  /// canvas is copied into it rather than blitted, which a software rasteriser does per pixel).
  Canvas(gpu::Context& context, bool ui, VkFormat format = VK_FORMAT_R8G8B8A8_UNORM);
  ~Canvas();
  Canvas(const Canvas&) = delete;
  Canvas& operator=(const Canvas&) = delete;

  /// (Re)creates the image for a width × height target (no-op when the size is unchanged).
  void resize(std::uint32_t width, std::uint32_t height);
  /// Encodes `frame` into the staging buffer (the previous submission using it must be complete)
  /// and records its upload and the UI pass; the image is left in TRANSFER_SRC_OPTIMAL.
  void record(VkCommandBuffer cmd, const Framebuffer& frame, ImDrawData* ui);
  /// The same for a frame on this canvas's device, used where it is: a kernel encodes it into
  /// a device buffer (the bytes encode_srgb8_into would write), copied into the image. No
  /// previous submission may still be using the canvas (as for the staging buffer). Throws
  /// std::invalid_argument for a frame of another device.
  void record(VkCommandBuffer cmd, const gpu::DeviceFrame& frame, ImDrawData* ui);
  /// Records a copy of the image (in TRANSFER_SRC_OPTIMAL) into the readback buffer.
  void record_readback(VkCommandBuffer cmd);
  /// The readback buffer's contents (RGBA whatever the format), after the commands of record_readback completed.
  [[nodiscard]] Rgba8Image readback() const;

  [[nodiscard]] const gpu::Image& image() const { return image_; }
  [[nodiscard]] std::uint32_t width() const { return width_; }
  [[nodiscard]] std::uint32_t height() const { return height_; }

private:
  struct DeviceEncoder;
  /// Copies `pixels` (the canvas's size, already encoded) into the image and draws the UI.
  void record_pixels(VkCommandBuffer cmd, const gpu::Buffer& pixels, ImDrawData* ui);

  gpu::Context& context_;
  std::unique_ptr<DeviceEncoder> encoder_; ///< made by the first device frame
  bool ui_ = false;
  VkFormat format_;
  VkRenderPass render_pass_ = VK_NULL_HANDLE;
  VkDescriptorPool ui_pool_ = VK_NULL_HANDLE;
  VkFramebuffer framebuffer_ = VK_NULL_HANDLE;
  gpu::Image image_;
  gpu::Buffer staging_, readback_;
  std::uint32_t width_ = 0, height_ = 0;
};

} // namespace specula::present
