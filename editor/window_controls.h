#pragma once
/// \file
/// What the editor window does with one poll's input (editor_window.cpp calls it every frame;
/// tests/editor feeds it made-up input): mouse and keys call the same session actions as
/// scripts and panels.
///   left click: select (a ray through the active tracer); left drag with X/Y/Z held: gizmo
///   (G translate, R rotate, T scale); right drag: orbit; right button + WASD/QE: fly;
///   F: frame selected; Ctrl+Z / Ctrl+Y: undo / redo; Delete: delete the selection.

#include "editor/core/editor_session.h"
#include "specula/present/window.h"

#include <optional>
#include <string>

namespace specula::editor {

/// Window pixel → frame pixel, undoing present()'s aspect-keeping letterbox; none outside the
/// frame.
std::optional<dvec2> window_to_frame(std::uint32_t window_width, std::uint32_t window_height,
                                     std::uint32_t frame_width, std::uint32_t frame_height,
                                     double x, double y);

class WindowControls {
public:
  /// Applies one poll's input to the session for a window of the given client size. An edit
  /// the session refuses (a drag that would make a scale zero, say) is kept in status().
  void apply(EditorSession& session, const present::InputState& in, std::uint32_t window_width,
             std::uint32_t window_height);

  [[nodiscard]] GizmoMode gizmo() const { return gizmo_; }
  /// The last refused edit's message, empty when none.
  [[nodiscard]] const std::string& status() const { return status_; }

private:
  GizmoMode gizmo_ = GizmoMode::Translate;
  double last_x_ = 0.0, last_y_ = 0.0; ///< where the left button went down or last dragged
  bool dragged_ = false;
  std::string status_;
};

} // namespace specula::editor
