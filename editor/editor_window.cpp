// The windowed editor over specula::present::Window. Compiled only where specula::present
// exists. Input is applied by WindowControls (window_controls.h), panels by draw_panels.
#include "editor/editor_window.h"

#include "editor/core/panels.h"
#include "editor/core/script.h"
#include "editor/window_controls.h"
#include "specula/image/image_io.h"
#include "specula/present/window.h"
#include "specula/render/resolution_governor.h"

#include "specula/trace/stats.h"

#include <imgui.h>

#include <chrono>
#include <cstdio>
#include <vector>

namespace specula::editor {

namespace {

/// An RGBA8 image as a PNG (alpha dropped: the canvas is opaque).
void write_rgba_png(const present::Rgba8Image& image, const std::filesystem::path& path) {
  std::vector<std::uint8_t> rgb(std::size_t(image.width) * image.height * 3);
  for (std::size_t i = 0, n = std::size_t(image.width) * image.height; i < n; ++i)
    for (int c = 0; c < 3; ++c) rgb[3 * i + std::size_t(c)] = image.rgba[4 * i + std::size_t(c)];
  write_png_srgb8(rgb, image.width, image.height, path);
}

class OffscreenUiCapture final : public UiCapture {
public:
  OffscreenUiCapture(std::uint32_t width, std::uint32_t height) {
    present::OffscreenSettings settings;
    settings.width = width;
    settings.height = height;
    settings.ui = true;
    target_ = present::Offscreen::create(settings);
  }

  void frame(EditorSession& session) override {
    // No platform backend moves ImGui's clock here: io.DeltaTime keeps its 1/60 s.
    target_->begin_ui();
    draw_panels(session, panels_);
    ImGui::Render();
  }

  void write(const EditorSession& session, const std::filesystem::path& png) override {
    write_rgba_png(target_->render(session.frame(), ImGui::GetDrawData()), png);
  }

private:
  std::unique_ptr<present::Offscreen> target_;
  PanelState panels_;
};

} // namespace

std::unique_ptr<UiCapture> UiCapture::create(std::uint32_t width, std::uint32_t height) {
  return std::make_unique<OffscreenUiCapture>(width, height);
}

int run_window(EditorSession& session, const WindowRun& run) {
  present::WindowSettings settings;
  settings.title = "Specula editor";
  settings.width = session.view().width;
  settings.height = session.view().height;
  settings.ui = true;
  const std::unique_ptr<present::Window> window = present::Window::open(settings);
  // A Vulkan backend renders on the window's device, its frames drawn where they are.
  session.share_device(window->context());
  if (!run.script.empty()) run_script(session, run.script);
  PanelState panels;
  WindowControls controls;
  present::InputState in;
  std::uint64_t shown = 0, in_place = 0; // frames presented; of them, from the device in place
  using Clock = std::chrono::steady_clock;
  const auto ms = [](Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
  };
  std::vector<double> frame_ms, tick_ms, present_ms; // poll to poll; the tick; UI + present
  std::vector<double> scales;
  ResolutionGovernor governor(run.target_fps > 0.0 ? 1e3 / run.target_fps : 0.0);
  Clock::time_point last = Clock::now();
  while ((!run.frames || shown < *run.frames) && window->poll(in)) {
    const Clock::time_point start = Clock::now();
    if (shown > 0) {
      frame_ms.push_back(ms(last, start));
      // Path and shadow modes refine over frames at one size: they render the full size.
      const float scale = governor.next(frame_ms.back());
      session.set_render_scale(stochastic_mode(session.view().mode) ? 1.0f : scale);
    }
    scales.push_back(stochastic_mode(session.view().mode) ? 1.0f : governor.scale());
    last = start;
    controls.apply(session, in, window->width(), window->height());
    if (!controls.status().empty()) panels.status = controls.status();
    session.tick();
    const Clock::time_point ticked = Clock::now();
    window->begin_ui();
    draw_panels(session, panels);
    ImGui::Render();
    if (const gpu::DeviceFrame* on_device = session.device_frame()) {
      window->present(*on_device, ImGui::GetDrawData());
      ++in_place;
    } else {
      window->present(session.frame(), ImGui::GetDrawData());
    }
    tick_ms.push_back(ms(start, ticked));
    present_ms.push_back(ms(ticked, Clock::now()));
    ++shown;
  }
  if (run.screenshot) session.screenshot(*run.screenshot);
  if (run.screenshot_ui) write_rgba_png(window->read_back(), *run.screenshot_ui);
  if (run.frames && !frame_ms.empty()) {
    // The presented rate, for docs/PERFORMANCE.md (a run with --frames is a measurement or a test).
    const double f = median(frame_ms);
    std::printf("specula-editor: %llu frames shown at %ux%u, median %.2f ms per frame (%.1f "
                "frames/s): tick %.2f ms, panels and present %.2f ms; render scale median %.3f; "
                "presented in place from the device: %llu\n",
                static_cast<unsigned long long>(shown), window->width(), window->height(), f,
                1e3 / f, median(tick_ms), median(present_ms), median(scales),
                static_cast<unsigned long long>(in_place));
  }
  return 0;
}

} // namespace specula::editor
