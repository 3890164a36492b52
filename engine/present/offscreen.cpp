#include "specula/present/canvas.h"

#include "specula/core/error.h"

#include <backends/imgui_impl_vulkan.h>
#include <imgui.h>

#include <stdexcept>

namespace specula::present {
namespace {

class OffscreenImpl final : public Offscreen {
public:
  explicit OffscreenImpl(const OffscreenSettings& settings) {
    if (settings.width == 0 || settings.height == 0)
      throw std::invalid_argument("an offscreen target needs a nonzero size, not " +
                                  std::to_string(settings.width) + "x" +
                                  std::to_string(settings.height));
    context_ = gpu::Context::create();
    if (settings.ui) {
      ui_ = ImGui::CreateContext();
      ImGui::SetCurrentContext(ui_);
      // The application may change it (the contract says it sets it); the target's size is
      // the natural default.
      ImGui::GetIO().DisplaySize = ImVec2(float(settings.width), float(settings.height));
      ImGui::GetIO().IniFilename = nullptr; // no imgui.ini written by headless runs
    }
    try {
      canvas_ = std::make_unique<Canvas>(*context_, settings.ui);
      canvas_->resize(settings.width, settings.height);
    } catch (...) {
      canvas_.reset();
      if (ui_ != nullptr) ImGui::DestroyContext(ui_);
      throw;
    }
  }
  ~OffscreenImpl() override {
    if (ui_ != nullptr) ImGui::SetCurrentContext(ui_);
    canvas_.reset();
    if (ui_ != nullptr) ImGui::DestroyContext(ui_);
  }

  void begin_ui() override {
    if (ui_ == nullptr) throw std::logic_error("Offscreen::begin_ui without OffscreenSettings::ui");
    ImGui::SetCurrentContext(ui_);
    ImGui_ImplVulkan_NewFrame();
    ImGui::NewFrame();
  }

  Rgba8Image render(const Framebuffer& frame, ImDrawData* ui) override { return draw(frame, ui); }
  Rgba8Image render(const gpu::DeviceFrame& frame, ImDrawData* ui) override {
    return draw(frame, ui);
  }
  [[nodiscard]] std::shared_ptr<gpu::Context> context() const override { return context_; }

private:
  template <class Frame>
  Rgba8Image draw(const Frame& frame, ImDrawData* ui) {
    if (ui_ != nullptr) ImGui::SetCurrentContext(ui_);
    context_->run_now([&](VkCommandBuffer cmd) {
      canvas_->record(cmd, frame, ui);
      canvas_->record_readback(cmd);
    });
    return canvas_->readback();
  }

  std::shared_ptr<gpu::Context> context_;
  ImGuiContext* ui_ = nullptr;
  std::unique_ptr<Canvas> canvas_;
};

} // namespace

std::unique_ptr<Offscreen> Offscreen::create(const OffscreenSettings& settings) {
  return std::make_unique<OffscreenImpl>(settings);
}

} // namespace specula::present
