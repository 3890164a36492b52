// The windowed editor over specula::present::Window. Compiled only where specula::present
// exists. Mouse and keys call the same session actions as scripts and panels:
//   left click: select (a ray through the active tracer); left drag with X/Y/Z held: gizmo
//   (G translate, R rotate, T scale); right drag: orbit; right button + WASD/QE: fly;
//   F: frame selected; Ctrl+Z / Ctrl+Y: undo / redo; Delete: delete the selection.
#include "editor/editor_window.h"

#include "editor/core/navigation.h"
#include "editor/core/panels.h"
#include "editor/core/script.h"
#include "specula/present/window.h"

#include <GLFW/glfw3.h>
#include <imgui.h>

#include <algorithm>

namespace specula::editor {

namespace {

/// Window pixel → frame pixel, undoing present()'s aspect-keeping letterbox.
std::optional<dvec2> to_frame(const present::Window& w, const Framebuffer& f, double x, double y) {
  const double scale = std::min(double(w.width()) / f.width(), double(w.height()) / f.height());
  const double ox = 0.5 * (w.width() - scale * f.width());
  const double oy = 0.5 * (w.height() - scale * f.height());
  const dvec2 p((x - ox) / scale, (y - oy) / scale);
  if (p.x < 0 || p.y < 0 || p.x >= f.width() || p.y >= f.height()) return std::nullopt;
  return p;
}

} // namespace

int run_window(EditorSession& session, const std::string& script) {
  present::WindowSettings settings;
  settings.title = "Specula editor";
  settings.width = session.view().width;
  settings.height = session.view().height;
  settings.ui = true;
  const std::unique_ptr<present::Window> window = present::Window::open(settings);
  if (!script.empty()) run_script(session, script);
  PanelState panels;
  present::InputState in;
  GizmoMode gizmo = GizmoMode::Translate;
  double last_x = 0.0, last_y = 0.0;
  bool dragged = false;
  while (window->poll(in)) {
    const bool ctrl = in.down[GLFW_KEY_LEFT_CONTROL] || in.down[GLFW_KEY_RIGHT_CONTROL];
    if (!in.ui_wants_keyboard) {
      if (ctrl && in.pressed[GLFW_KEY_Z]) session.undo();
      if (ctrl && in.pressed[GLFW_KEY_Y]) session.redo();
      if (in.pressed[GLFW_KEY_F]) session.frame_selected();
      if (in.pressed[GLFW_KEY_G]) gizmo = GizmoMode::Translate;
      if (in.pressed[GLFW_KEY_R]) gizmo = GizmoMode::Rotate;
      if (in.pressed[GLFW_KEY_T]) gizmo = GizmoMode::Scale;
      if (in.pressed[GLFW_KEY_DELETE] && session.selected()) session.remove(*session.selected());
    }
    if (!in.ui_wants_mouse) {
      if (in.button_pressed[0]) {
        last_x = in.mouse_x;
        last_y = in.mouse_y;
        dragged = false;
      }
      const int axis = in.down[GLFW_KEY_X]   ? 0
                       : in.down[GLFW_KEY_Y] ? 1
                       : in.down[GLFW_KEY_Z] ? 2
                                             : -1;
      if (in.button_down[0] && axis >= 0 && session.selected() &&
          (in.mouse_x != last_x || in.mouse_y != last_y)) {
        // Window pixels to frame pixels: the gizmo works in the frame's own pixels.
        const auto a = to_frame(*window, session.frame(), last_x, last_y);
        const auto b = to_frame(*window, session.frame(), in.mouse_x, in.mouse_y);
        if (a && b) {
          try {
            session.drag(gizmo, axis, *b - *a);
          } catch (const std::exception& e) {
            panels.status = e.what();
          }
        }
        last_x = in.mouse_x;
        last_y = in.mouse_y;
        dragged = true;
      }
      if (in.button_released[0] && !dragged)
        if (const auto p = to_frame(*window, session.frame(), in.mouse_x, in.mouse_y))
          (void)session.click(std::uint32_t(p->x), std::uint32_t(p->y));
      if (in.button_down[1]) {
        const dvec3 move(double(in.down[GLFW_KEY_D]) - double(in.down[GLFW_KEY_A]),
                         double(in.down[GLFW_KEY_E]) - double(in.down[GLFW_KEY_Q]),
                         double(in.down[GLFW_KEY_W]) - double(in.down[GLFW_KEY_S]));
        if (move != dvec3(0.0))
          session.set_camera(
              fly(session.camera(), move, 1.0 / 60.0, 2.0, in.mouse_dx, in.mouse_dy));
        else if (in.mouse_dx != 0.0 || in.mouse_dy != 0.0)
          session.set_camera(orbit(session.camera(), in.mouse_dx, in.mouse_dy));
      }
    }
    session.tick();
    window->begin_ui();
    draw_panels(session, panels);
    ImGui::Render();
    window->present(session.frame(), ImGui::GetDrawData());
  }
  return 0;
}

} // namespace specula::editor
