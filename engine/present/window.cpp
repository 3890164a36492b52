#include "specula/core/error.h"
#include "specula/present/canvas.h"
#include "specula/present/input.h"

#define GLFW_INCLUDE_VULKAN
#include <GLFW/glfw3.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_vulkan.h>
#include <imgui.h>

#include <algorithm>
#include <cstdint>
#include <future>
#include <limits>
#include <mutex>

namespace specula::present {
namespace {

/// GLFW's last error, as the reason an UnavailableError gives.
std::string glfw_error() {
  const char* text = nullptr;
  const int code = glfwGetError(&text);
  if (code == GLFW_NO_ERROR) return "no reason given";
  return text != nullptr ? std::string(text) : "error " + std::to_string(code);
}

/// GLFW is initialised while a window is open (glfwInit and glfwTerminate bracket them all).
int g_glfw_users = 0;

void glfw_acquire() {
  if (g_glfw_users == 0 && glfwInit() != GLFW_TRUE)
    throw UnavailableError("cannot open a window: " + glfw_error());
  ++g_glfw_users;
}

void glfw_release() {
  if (--g_glfw_users == 0) glfwTerminate();
}

class WindowImpl final : public Window {
public:
  explicit WindowImpl(const WindowSettings& settings) : vsync_(settings.vsync) {
    if (settings.width == 0 || settings.height == 0)
      throw std::invalid_argument("a window needs a nonzero size");
    glfw_acquire();
    try {
      open(settings);
    } catch (...) {
      destroy();
      throw;
    }
  }
  ~WindowImpl() override { destroy(); }

  bool poll(InputState& input) override {
    // ImGui's GLFW callbacks feed the current context.
    if (ui_ != nullptr) ImGui::SetCurrentContext(ui_);
    glfwPollEvents();
    tracker_.finish(input);
    if (ui_ != nullptr) {
      const ImGuiIO& io = ImGui::GetIO();
      input.ui_wants_mouse = io.WantCaptureMouse;
      input.ui_wants_keyboard = io.WantCaptureKeyboard;
    }
    return glfwWindowShouldClose(window_) == GLFW_FALSE;
  }

  void begin_ui() override {
    if (ui_ == nullptr) throw std::logic_error("Window::begin_ui without WindowSettings::ui");
    ImGui::SetCurrentContext(ui_);
    ImGui_ImplVulkan_NewFrame();
    ImGui_ImplGlfw_NewFrame();
    ImGui::NewFrame();
  }

  void present(const Framebuffer& frame, ImDrawData* ui) override {
    present_with([&] { canvas_->record(cmd_, frame, ui); });
  }

  void present(const gpu::DeviceFrame& frame, ImDrawData* ui) override {
    present_with([&] { canvas_->record(cmd_, frame, ui); });
  }

  [[nodiscard]] std::shared_ptr<gpu::Context> context() const override { return context_; }

  /// present(): `record` records the canvas's commands into cmd_.
  template <class Record>
  void present_with(const Record& record) {
    finish_presenting();
    const VkDevice device = context_->device();
    gpu::check(vkWaitForFences(device, 1, &fence_, VK_TRUE, UINT64_MAX), "vkWaitForFences");
    std::uint32_t index = 0;
    for (int attempt = 0;; ++attempt) {
      if (stale_ || swapchain_ == VK_NULL_HANDLE) make_swapchain();
      if (swapchain_ == VK_NULL_HANDLE) return; // minimised: nothing to draw into
      const VkResult r =
          vkAcquireNextImageKHR(device, swapchain_, UINT64_MAX, acquired_, VK_NULL_HANDLE, &index);
      if (r == VK_SUCCESS) break;
      if (r == VK_SUBOPTIMAL_KHR) { // still presentable: use it, recreate for the next frame
        stale_ = true;
        break;
      }
      if (r != VK_ERROR_OUT_OF_DATE_KHR || attempt == 2) gpu::check(r, "vkAcquireNextImageKHR");
      stale_ = true;
    }
    if (ui_ != nullptr) ImGui::SetCurrentContext(ui_);
    canvas_->resize(extent_.width, extent_.height);

    gpu::check(vkResetCommandBuffer(cmd_, 0), "vkResetCommandBuffer");
    VkCommandBufferBeginInfo bi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    gpu::check(vkBeginCommandBuffer(cmd_, &bi), "vkBeginCommandBuffer");
    record();
    copy_to_swapchain(images_[index]);
    gpu::check(vkEndCommandBuffer(cmd_), "vkEndCommandBuffer");

    // The copy into the swapchain image waits for the presentation engine to release it.
    const VkPipelineStageFlags wait_stage = VK_PIPELINE_STAGE_TRANSFER_BIT;
    VkSubmitInfo si{VK_STRUCTURE_TYPE_SUBMIT_INFO};
    si.waitSemaphoreCount = 1;
    si.pWaitSemaphores = &acquired_;
    si.pWaitDstStageMask = &wait_stage;
    si.commandBufferCount = 1;
    si.pCommandBuffers = &cmd_;
    si.signalSemaphoreCount = 1;
    si.pSignalSemaphores = &rendered_[index];
    gpu::check(vkResetFences(device, 1, &fence_), "vkResetFences");
    {
      const std::unique_lock<std::mutex> lock = context_->lock_queue();
      gpu::check(vkQueueSubmit(context_->queue(), 1, &si, fence_), "vkQueueSubmit");
    }
    presented_ = true;

    // The present on a thread of its own, so that the next frame's tick goes on meanwhile: on
    // lavapipe the call waits for the copy and the panels' pass to run, then hands the image to
    // the X server (3-7 ms of a 960x540 frame). The queue and the swapchain are touched again
    // only after finish_presenting(), the queue by a tracer sharing the device under its lock.
    presenting_ = std::async(std::launch::async, [context = context_.get(), swapchain = swapchain_,
                                                  wait = rendered_[index], index] {
      VkPresentInfoKHR pi{VK_STRUCTURE_TYPE_PRESENT_INFO_KHR};
      pi.waitSemaphoreCount = 1;
      pi.pWaitSemaphores = &wait;
      pi.swapchainCount = 1;
      pi.pSwapchains = &swapchain;
      pi.pImageIndices = &index;
      const std::unique_lock<std::mutex> lock = context->lock_queue();
      return vkQueuePresentKHR(context->queue(), &pi);
    });
  }

  void set_size(std::uint32_t width, std::uint32_t height) override {
    if (width == 0 || height == 0) throw std::invalid_argument("a window needs a nonzero size");
    glfwSetWindowSize(window_, int(width), int(height));
  }

  [[nodiscard]] std::uint32_t width() const override { return framebuffer_size().width; }
  [[nodiscard]] std::uint32_t height() const override { return framebuffer_size().height; }
  [[nodiscard]] std::string device_name() const override { return context_->info().name; }

  [[nodiscard]] Rgba8Image read_back() override {
    if (!presented_) return {};
    finish_presenting();
    gpu::check(vkWaitForFences(context_->device(), 1, &fence_, VK_TRUE, UINT64_MAX),
               "vkWaitForFences");
    context_->run_now([&](VkCommandBuffer cmd) { canvas_->record_readback(cmd); });
    return canvas_->readback();
  }

private:
  void open(const WindowSettings& settings) {
    if (glfwVulkanSupported() != GLFW_TRUE)
      throw UnavailableError("cannot open a window: GLFW finds no Vulkan loader");
    glfwWindowHint(GLFW_CLIENT_API, GLFW_NO_API);
    window_ = glfwCreateWindow(int(settings.width), int(settings.height), settings.title.c_str(),
                               nullptr, nullptr);
    if (window_ == nullptr) throw UnavailableError("cannot open a window: " + glfw_error());
    glfwSetWindowUserPointer(window_, this);
    install_callbacks();

    gpu::Context::Options options;
    std::uint32_t count = 0;
    const char** required = glfwGetRequiredInstanceExtensions(&count);
    if (required == nullptr) throw UnavailableError("cannot present: " + glfw_error());
    options.instance_extensions.assign(required, required + count);
    options.device_extensions = {VK_KHR_SWAPCHAIN_EXTENSION_NAME};
    options.accept = [this](VkInstance instance, VkPhysicalDevice device, std::uint32_t family) {
      if (surface_ == VK_NULL_HANDLE)
        gpu::check(glfwCreateWindowSurface(instance, window_, nullptr, &surface_),
                   "glfwCreateWindowSurface");
      VkBool32 supported = VK_FALSE;
      return vkGetPhysicalDeviceSurfaceSupportKHR(device, family, surface_, &supported) ==
                 VK_SUCCESS &&
             supported == VK_TRUE;
    };
    try {
      context_ = gpu::Context::create(options);
    } catch (...) {
      surface_ = VK_NULL_HANDLE; // went with the instance the failed create destroyed
      throw;
    }
    if (surface_ == VK_NULL_HANDLE) throw UnavailableError("cannot present: no window surface");

    if (settings.ui) {
      ui_ = ImGui::CreateContext();
      ImGui::SetCurrentContext(ui_);
      // No imgui.ini in the working directory unless the application names one.
      ImGui::GetIO().IniFilename = nullptr;
      // Chains to the callbacks installed above, so the application's input sees every event.
      ImGui_ImplGlfw_InitForVulkan(window_, true);
      glfw_ui_ = true;
    }
    canvas_ = std::make_unique<Canvas>(*context_, settings.ui, surface_format().format);

    const VkDevice device = context_->device();
    VkSemaphoreCreateInfo sci{VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO};
    gpu::check(vkCreateSemaphore(device, &sci, nullptr, &acquired_), "vkCreateSemaphore");
    VkFenceCreateInfo fci{VK_STRUCTURE_TYPE_FENCE_CREATE_INFO};
    fci.flags = VK_FENCE_CREATE_SIGNALED_BIT; // the first present has nothing to wait for
    gpu::check(vkCreateFence(device, &fci, nullptr, &fence_), "vkCreateFence");
    VkCommandBufferAllocateInfo ai{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
    ai.commandPool = context_->command_pool();
    ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    ai.commandBufferCount = 1;
    gpu::check(vkAllocateCommandBuffers(device, &ai, &cmd_), "vkAllocateCommandBuffers");
    make_swapchain();
  }

  void install_callbacks() {
    glfwSetKeyCallback(window_, [](GLFWwindow* w, int key, int, int action, int) {
      if (action != GLFW_REPEAT) self(w).tracker_.key(key, action == GLFW_PRESS);
    });
    glfwSetMouseButtonCallback(window_, [](GLFWwindow* w, int button, int action, int) {
      self(w).tracker_.button(button, action == GLFW_PRESS);
    });
    glfwSetCursorPosCallback(window_, [](GLFWwindow* w, double x, double y) {
      self(w).tracker_.cursor(x, y);
    });
    glfwSetScrollCallback(window_, [](GLFWwindow* w, double, double dy) {
      self(w).tracker_.scroll(dy);
    });
    glfwSetWindowCloseCallback(window_, [](GLFWwindow* w) { self(w).tracker_.close(); });
    glfwSetFramebufferSizeCallback(window_, [](GLFWwindow* w, int, int) { self(w).stale_ = true; });
  }

  static WindowImpl& self(GLFWwindow* w) {
    return *static_cast<WindowImpl*>(glfwGetWindowUserPointer(w));
  }

  [[nodiscard]] VkExtent2D framebuffer_size() const {
    int w = 0, h = 0;
    glfwGetFramebufferSize(window_, &w, &h);
    return {std::uint32_t(std::max(w, 0)), std::uint32_t(std::max(h, 0))};
  }

  /// The swapchain's format: UNORM, as the values are sRGB-encoded already (an _SRGB format
  /// would encode them again).
  [[nodiscard]] VkSurfaceFormatKHR surface_format() const {
    const VkPhysicalDevice physical = context_->physical_device();
    std::uint32_t count = 0;
    gpu::check(vkGetPhysicalDeviceSurfaceFormatsKHR(physical, surface_, &count, nullptr),
               "vkGetPhysicalDeviceSurfaceFormatsKHR");
    std::vector<VkSurfaceFormatKHR> formats(count);
    gpu::check(vkGetPhysicalDeviceSurfaceFormatsKHR(physical, surface_, &count, formats.data()),
               "vkGetPhysicalDeviceSurfaceFormatsKHR");
    const auto format = std::find_if(formats.begin(), formats.end(), [](VkSurfaceFormatKHR f) {
      return (f.format == VK_FORMAT_B8G8R8A8_UNORM || f.format == VK_FORMAT_R8G8B8A8_UNORM) &&
             f.colorSpace == VK_COLOR_SPACE_SRGB_NONLINEAR_KHR;
    });
    if (format == formats.end())
      throw UnavailableError("cannot present: the surface offers no 8-bit UNORM sRGB format");
    return *format;
  }

  /// (Re)creates the swapchain for the surface's current extent; none while it is zero.
  void make_swapchain() {
    const VkDevice device = context_->device();
    const VkPhysicalDevice physical = context_->physical_device();
    context_->wait_idle();
    stale_ = false;
    VkSurfaceCapabilitiesKHR caps;
    gpu::check(vkGetPhysicalDeviceSurfaceCapabilitiesKHR(physical, surface_, &caps),
               "vkGetPhysicalDeviceSurfaceCapabilitiesKHR");
    VkExtent2D extent = caps.currentExtent;
    if (extent.width == std::numeric_limits<std::uint32_t>::max()) { // the window decides
      extent = framebuffer_size();
      extent.width = std::clamp(extent.width, caps.minImageExtent.width, caps.maxImageExtent.width);
      extent.height =
          std::clamp(extent.height, caps.minImageExtent.height, caps.maxImageExtent.height);
    }
    if (extent.width == 0 || extent.height == 0) {
      destroy_swapchain();
      return;
    }
    if ((caps.supportedUsageFlags & VK_IMAGE_USAGE_TRANSFER_DST_BIT) == 0)
      throw UnavailableError("cannot present: the surface's images cannot be copied into");

    const VkSurfaceFormatKHR format = surface_format();
    std::uint32_t count = 0;
    gpu::check(vkGetPhysicalDeviceSurfacePresentModesKHR(physical, surface_, &count, nullptr),
               "vkGetPhysicalDeviceSurfacePresentModesKHR");
    std::vector<VkPresentModeKHR> modes(count);
    gpu::check(vkGetPhysicalDeviceSurfacePresentModesKHR(physical, surface_, &count, modes.data()),
               "vkGetPhysicalDeviceSurfacePresentModesKHR");
    VkPresentModeKHR mode = VK_PRESENT_MODE_FIFO_KHR; // always offered
    if (!vsync_)
      for (VkPresentModeKHR want : {VK_PRESENT_MODE_MAILBOX_KHR, VK_PRESENT_MODE_IMMEDIATE_KHR})
        if (mode == VK_PRESENT_MODE_FIFO_KHR && std::count(modes.begin(), modes.end(), want) > 0)
          mode = want;

    VkSwapchainCreateInfoKHR sci{VK_STRUCTURE_TYPE_SWAPCHAIN_CREATE_INFO_KHR};
    sci.surface = surface_;
    sci.minImageCount = caps.minImageCount + 1;
    if (caps.maxImageCount > 0) sci.minImageCount = std::min(sci.minImageCount, caps.maxImageCount);
    sci.imageFormat = format.format;
    sci.imageColorSpace = format.colorSpace;
    sci.imageExtent = extent;
    sci.imageArrayLayers = 1;
    sci.imageUsage = VK_IMAGE_USAGE_TRANSFER_DST_BIT;
    sci.imageSharingMode = VK_SHARING_MODE_EXCLUSIVE;
    sci.preTransform = caps.currentTransform;
    sci.compositeAlpha = VK_COMPOSITE_ALPHA_OPAQUE_BIT_KHR; // else the first one offered
    for (std::uint32_t bit = 1; (caps.supportedCompositeAlpha & sci.compositeAlpha) == 0 && bit != 0;
         bit <<= 1)
      sci.compositeAlpha = VkCompositeAlphaFlagBitsKHR(bit);
    sci.presentMode = mode;
    sci.clipped = VK_TRUE;
    sci.oldSwapchain = swapchain_;
    VkSwapchainKHR created = VK_NULL_HANDLE;
    gpu::check(vkCreateSwapchainKHR(device, &sci, nullptr, &created), "vkCreateSwapchainKHR");
    destroy_swapchain();
    swapchain_ = created;
    swap_format_ = format.format;
    extent_ = extent;
    gpu::check(vkGetSwapchainImagesKHR(device, swapchain_, &count, nullptr), "vkGetSwapchainImagesKHR");
    images_.resize(count);
    gpu::check(vkGetSwapchainImagesKHR(device, swapchain_, &count, images_.data()),
               "vkGetSwapchainImagesKHR");
    // One "rendered" semaphore per image: a present may still wait on the previous one's.
    VkSemaphoreCreateInfo semi{VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO};
    rendered_.assign(count, VK_NULL_HANDLE);
    for (VkSemaphore& s : rendered_)
      gpu::check(vkCreateSemaphore(device, &semi, nullptr, &s), "vkCreateSemaphore");
  }

  void destroy_swapchain() noexcept {
    if (context_ == nullptr) return;
    for (VkSemaphore s : rendered_) vkDestroySemaphore(context_->device(), s, nullptr);
    rendered_.clear();
    images_.clear();
    if (swapchain_ != VK_NULL_HANDLE) vkDestroySwapchainKHR(context_->device(), swapchain_, nullptr);
    swapchain_ = VK_NULL_HANDLE;
    extent_ = {0, 0};
  }

  /// Copies the canvas (TRANSFER_SRC_OPTIMAL, the swapchain's size) into a swapchain image and
  /// hands that to presentation; a blit should the formats differ.
  void copy_to_swapchain(VkImage target) {
    gpu::image_barrier(cmd_, target, VK_IMAGE_ASPECT_COLOR_BIT, VK_IMAGE_LAYOUT_UNDEFINED,
                       VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, VK_PIPELINE_STAGE_TRANSFER_BIT, 0,
                       VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT);
    const VkImageSubresourceLayers layers{VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1};
    if (swap_format_ == canvas_->image().format()) {
      VkImageCopy region{};
      region.srcSubresource = region.dstSubresource = layers;
      region.extent = {extent_.width, extent_.height, 1};
      vkCmdCopyImage(cmd_, canvas_->image().handle(), VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, target,
                     VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &region);
    } else {
      VkImageBlit region{};
      region.srcSubresource = region.dstSubresource = layers;
      region.srcOffsets[1] = region.dstOffsets[1] = {int(extent_.width), int(extent_.height), 1};
      vkCmdBlitImage(cmd_, canvas_->image().handle(), VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, target,
                     VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, 1, &region, VK_FILTER_NEAREST);
    }
    gpu::image_barrier(cmd_, target, VK_IMAGE_ASPECT_COLOR_BIT,
                       VK_IMAGE_LAYOUT_TRANSFER_DST_OPTIMAL, VK_IMAGE_LAYOUT_PRESENT_SRC_KHR,
                       VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                       VK_PIPELINE_STAGE_BOTTOM_OF_PIPE_BIT, 0);
  }

  /// Waits for the last frame's present (present()) and takes its result: an out-of-date or
  /// suboptimal swapchain is recreated at the next present, any other failure throws.
  void finish_presenting() {
    if (!presenting_.valid()) return;
    const VkResult r = presenting_.get();
    if (r == VK_ERROR_OUT_OF_DATE_KHR || r == VK_SUBOPTIMAL_KHR)
      stale_ = true;
    else
      gpu::check(r, "vkQueuePresentKHR");
  }

  /// Releases whatever open() got to, in reverse order.
  void destroy() noexcept {
    if (presenting_.valid()) (void)presenting_.get(); // the result no longer matters
    if (context_ != nullptr) try {
        context_->wait_idle();
      } catch (const gpu::GpuError&) { // a lost device: nothing runs any more
      }
    if (ui_ != nullptr) ImGui::SetCurrentContext(ui_);
    canvas_.reset();
    if (glfw_ui_) ImGui_ImplGlfw_Shutdown();
    if (ui_ != nullptr) ImGui::DestroyContext(ui_);
    ui_ = nullptr;
    destroy_swapchain();
    if (context_ != nullptr) {
      const VkDevice device = context_->device();
      if (cmd_ != VK_NULL_HANDLE) vkFreeCommandBuffers(device, context_->command_pool(), 1, &cmd_);
      if (fence_ != VK_NULL_HANDLE) vkDestroyFence(device, fence_, nullptr);
      if (acquired_ != VK_NULL_HANDLE) vkDestroySemaphore(device, acquired_, nullptr);
      if (surface_ != VK_NULL_HANDLE) vkDestroySurfaceKHR(context_->instance(), surface_, nullptr);
    }
    context_.reset();
    if (window_ != nullptr) glfwDestroyWindow(window_);
    window_ = nullptr;
    glfw_release();
  }

  bool vsync_ = false;
  GLFWwindow* window_ = nullptr;
  /// Shared with tracers rendering on the window's device (context()).
  std::shared_ptr<gpu::Context> context_;
  VkSurfaceKHR surface_ = VK_NULL_HANDLE;
  ImGuiContext* ui_ = nullptr;
  bool glfw_ui_ = false;
  std::unique_ptr<Canvas> canvas_;
  VkSwapchainKHR swapchain_ = VK_NULL_HANDLE;
  VkFormat swap_format_ = VK_FORMAT_UNDEFINED;
  VkExtent2D extent_{0, 0};
  std::vector<VkImage> images_;
  std::vector<VkSemaphore> rendered_;
  VkSemaphore acquired_ = VK_NULL_HANDLE;
  VkFence fence_ = VK_NULL_HANDLE;
  VkCommandBuffer cmd_ = VK_NULL_HANDLE;
  bool stale_ = false;
  bool presented_ = false;
  std::future<VkResult> presenting_; ///< the last frame's vkQueuePresentKHR (present())
  InputTracker tracker_;
};

} // namespace

std::unique_ptr<Window> Window::open(const WindowSettings& settings) {
  return std::make_unique<WindowImpl>(settings);
}

} // namespace specula::present
