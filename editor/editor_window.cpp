// The windowed editor over specula::present::Window. Compiled only where specula::present
// exists. Input is applied by WindowControls (window_controls.h), panels by draw_panels.
#include "editor/editor_window.h"

#include "editor/core/panels.h"
#include "editor/core/script.h"
#include "editor/window_controls.h"
#include "specula/present/window.h"

#include <imgui.h>

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
  while ((!run.frames || shown < *run.frames) && window->poll(in)) {
    controls.apply(session, in, window->width(), window->height());
    if (!controls.status().empty()) panels.status = controls.status();
    session.tick();
    window->begin_ui();
    draw_panels(session, panels);
    ImGui::Render();
    window->present(session.frame(), ImGui::GetDrawData());
    ++shown;
  }
  if (run.screenshot) session.screenshot(*run.screenshot);
  return 0;
}

} // namespace specula::editor
