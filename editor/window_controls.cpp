#include "editor/window_controls.h"

#include "editor/core/navigation.h"

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include <algorithm>
#include <exception>

namespace specula::editor {

std::optional<dvec2> window_to_frame(std::uint32_t window_width, std::uint32_t window_height,
                                     std::uint32_t frame_width, std::uint32_t frame_height,
                                     double x, double y) {
  const double fw = frame_width, fh = frame_height;
  const double scale = std::min(double(window_width) / fw, double(window_height) / fh);
  if (!(scale > 0.0)) return std::nullopt;
  const double ox = 0.5 * (double(window_width) - scale * fw);
  const double oy = 0.5 * (double(window_height) - scale * fh);
  const dvec2 p((x - ox) / scale, (y - oy) / scale);
  if (!(p.x >= 0.0 && p.y >= 0.0 && p.x < fw && p.y < fh)) return std::nullopt;
  return p;
}

void WindowControls::apply(EditorSession& session, const present::InputState& in,
                           std::uint32_t window_width, std::uint32_t window_height) {
  const auto down = [&](int key) { return in.down[std::size_t(key)]; };
  const auto pressed = [&](int key) { return in.pressed[std::size_t(key)]; };
  if (!in.ui_wants_keyboard) {
    const bool ctrl = down(GLFW_KEY_LEFT_CONTROL) || down(GLFW_KEY_RIGHT_CONTROL);
    if (ctrl && pressed(GLFW_KEY_Z)) session.undo();
    if (ctrl && pressed(GLFW_KEY_Y)) session.redo();
    if (pressed(GLFW_KEY_F)) session.frame_selected();
    if (pressed(GLFW_KEY_G)) gizmo_ = GizmoMode::Translate;
    if (pressed(GLFW_KEY_R)) gizmo_ = GizmoMode::Rotate;
    if (pressed(GLFW_KEY_T)) gizmo_ = GizmoMode::Scale;
    if (pressed(GLFW_KEY_DELETE) && session.selected()) session.remove(*session.selected());
  }
  if (in.ui_wants_mouse) {
    if (in.button_released[0]) session.end_gesture(); // a drag that ended over a panel
    return;
  }
  const auto to_frame = [&](double x, double y) {
    const auto [fw, fh] = session.frame_size();
    return window_to_frame(window_width, window_height, fw, fh, x, y);
  };
  if (in.button_pressed[0]) {
    last_x_ = in.mouse_x;
    last_y_ = in.mouse_y;
    dragged_ = false;
    session.begin_gesture(); // the whole drag is one undo step
  }
  const int axis = down(GLFW_KEY_X) ? 0 : down(GLFW_KEY_Y) ? 1 : down(GLFW_KEY_Z) ? 2 : -1;
  if (in.button_down[0] && axis >= 0 && session.selected() &&
      (in.mouse_x != last_x_ || in.mouse_y != last_y_)) {
    // The gizmo works in the frame's own pixels.
    const auto a = to_frame(last_x_, last_y_);
    const auto b = to_frame(in.mouse_x, in.mouse_y);
    if (a && b) {
      try {
        session.drag(gizmo_, axis, *b - *a);
        status_.clear();
      } catch (const std::exception& e) {
        status_ = e.what();
      }
    }
    last_x_ = in.mouse_x;
    last_y_ = in.mouse_y;
    dragged_ = true;
  }
  if (in.button_released[0]) {
    session.end_gesture();
    if (!dragged_)
      if (const auto p = to_frame(in.mouse_x, in.mouse_y))
        (void)session.click(std::uint32_t(p->x), std::uint32_t(p->y));
  }
  if (in.button_down[1]) {
    const dvec3 move(double(down(GLFW_KEY_D)) - double(down(GLFW_KEY_A)),
                     double(down(GLFW_KEY_E)) - double(down(GLFW_KEY_Q)),
                     double(down(GLFW_KEY_W)) - double(down(GLFW_KEY_S)));
    if (move != dvec3(0.0))
      session.set_camera(fly(session.camera(), move, 1.0 / 60.0, 2.0, in.mouse_dx, in.mouse_dy));
    else if (in.mouse_dx != 0.0 || in.mouse_dy != 0.0)
      session.set_camera(orbit(session.camera(), in.mouse_dx, in.mouse_dy));
  }
}

} // namespace specula::editor
