// The windowed editor over specula::present::Window. Compiled only where specula::present
// exists. Input is applied by WindowControls (window_controls.h), panels by draw_panels.
#include "editor/editor_window.h"

#include "editor/core/panels.h"
#include "editor/core/script.h"
#include "editor/window_controls.h"
#include "specula/present/window.h"
#include "specula/render/resolution_governor.h"

#include "specula/trace/stats.h"

#include <imgui.h>

#include <chrono>
#include <cstdio>
#include <vector>

namespace specula::editor {

int run_window(EditorSession& session, const WindowRun& run) {
  present::WindowSettings settings;
  settings.title = "Specula editor";
  settings.width = session.view().width;
  settings.height = session.view().height;
  settings.ui = true;
  const std::unique_ptr<present::Window> window = present::Window::open(settings);
  if (!run.script.empty()) run_script(session, run.script);
  PanelState panels;
  WindowControls controls;
  present::InputState in;
  std::uint64_t shown = 0;
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
    window->present(session.frame(), ImGui::GetDrawData());
    tick_ms.push_back(ms(start, ticked));
    present_ms.push_back(ms(ticked, Clock::now()));
    ++shown;
  }
  if (run.screenshot) session.screenshot(*run.screenshot);
  if (run.frames && !frame_ms.empty()) {
    // The presented rate, for docs/PERFORMANCE.md (a run with --frames is a measurement or a test).
    const double f = median(frame_ms);
    std::printf("specula-editor: %llu frames shown at %ux%u, median %.2f ms per frame (%.1f "
                "frames/s): tick %.2f ms, panels and present %.2f ms; render scale median %.3f\n",
                static_cast<unsigned long long>(shown), window->width(), window->height(), f,
                1e3 / f, median(tick_ms), median(present_ms), median(scales));
  }
  return 0;
}

} // namespace specula::editor
