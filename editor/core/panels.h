#pragma once
/// \file
/// The editor's Dear ImGui panels: plain functions over the session. Every edit a panel makes
/// calls the session's actions (the same ones scripts and the viewport's mouse use), so panel
/// edits are undoable like any other. No backend is needed to build them: HeadlessUi runs them
/// with a bare context (tests, --headless), a window's backends draw them (editor_window.cpp).

#include "editor/core/editor_session.h"

#include <string>

namespace specula::editor {

/// What the panels keep between frames (not part of the scene or the undo history).
struct PanelState {
  std::string status; ///< the last action's error, shown until the next action succeeds
};

/// A panel's rectangle in display pixels (origin top left).
struct PanelRect {
  float x = 0.0f, y = 0.0f, width = 0.0f, height = 0.0f;
};

/// Where the panels open on a display of width × height (Dear ImGui's FirstUseEver: a person may
/// move and resize them afterwards): the entity tree and the inspector down the left edge, the
/// render settings, the frame plots and the cache panel down the right, each column a quarter of
/// the width (180 to 320 pixels), so the middle of the viewport stays clear. Without it every
/// panel opened at ImGui's default spot, one on top of the other.
struct PanelLayout {
  PanelRect entities, inspector, render, frame, caches;
};
[[nodiscard]] PanelLayout panel_layout(float width, float height);

/// Entity tree (the Parent hierarchy; click selects, drag onto another entity reparents, onto
/// the root entry unparents), inspector, render settings, overlay plot and cache view.
void draw_panels(EditorSession& session, PanelState& state);

void entity_tree_panel(EditorSession& session, PanelState& state);
void inspector_panel(EditorSession& session, PanelState& state);
void render_settings_panel(EditorSession& session, PanelState& state);
/// Per-system ms and rays per second over the session's history.
void overlay_panel(EditorSession& session);
/// Valid / outdated texels per cached object; the visibility-graph edges of the selection's cube.
void cache_panel(EditorSession& session);

/// A Dear ImGui context without any backend (io.DisplaySize set, font atlas built on the CPU):
/// frame() runs NewFrame, the panels and Render, so the panels run headless.
class HeadlessUi {
public:
  HeadlessUi(float width, float height);
  ~HeadlessUi();
  HeadlessUi(const HeadlessUi&) = delete;
  HeadlessUi& operator=(const HeadlessUi&) = delete;
  void frame(EditorSession& session);
  [[nodiscard]] const PanelState& state() const { return state_; }

private:
  PanelState state_;
};

} // namespace specula::editor
