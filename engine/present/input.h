#pragma once
/// \file
/// The bookkeeping behind Window::poll, apart from GLFW so it can be tested: events arrive one by
/// one (GLFW's callbacks), and finish() turns them into the held state and the edges since the
/// previous poll. A key pressed and released between two polls reports pressed but not down.

#include "specula/present/window.h"

namespace specula::present {

class InputTracker {
public:
  void key(int key, bool down) {
    if (key < 0 || key >= InputState::kKeyCount) return; // GLFW_KEY_UNKNOWN (-1) and the like
    down_[std::size_t(key)] = down;
    if (down) pressed_[std::size_t(key)] = true;
  }
  void button(int button, bool down) {
    if (button < 0 || button >= 3) return; // buttons 4..8 are not tracked
    button_down_[std::size_t(button)] = down;
    (down ? button_pressed_ : button_released_)[std::size_t(button)] = true;
  }
  void cursor(double x, double y) {
    if (!has_cursor_) {
      // The first position is not a motion: the cursor did not move from (0, 0).
      last_x_ = x;
      last_y_ = y;
      has_cursor_ = true;
    }
    mouse_x_ = x;
    mouse_y_ = y;
  }
  void scroll(double dy) { scroll_ += dy; }
  void close() { close_ = true; }

  /// Writes the state since the previous finish() into `input` (ui_wants_* untouched).
  void finish(InputState& input) {
    input.down = down_;
    input.pressed = pressed_;
    input.button_down = button_down_;
    input.button_pressed = button_pressed_;
    input.button_released = button_released_;
    input.mouse_x = mouse_x_;
    input.mouse_y = mouse_y_;
    input.mouse_dx = mouse_x_ - last_x_;
    input.mouse_dy = mouse_y_ - last_y_;
    input.scroll = scroll_;
    input.close_requested = close_;
    pressed_ = {};
    button_pressed_ = {};
    button_released_ = {};
    last_x_ = mouse_x_;
    last_y_ = mouse_y_;
    scroll_ = 0.0;
  }

private:
  std::array<bool, InputState::kKeyCount> down_{}, pressed_{};
  std::array<bool, 3> button_down_{}, button_pressed_{}, button_released_{};
  double mouse_x_ = 0.0, mouse_y_ = 0.0, last_x_ = 0.0, last_y_ = 0.0, scroll_ = 0.0;
  bool has_cursor_ = false;
  bool close_ = false;
};

} // namespace specula::present
