#pragma once
/// \file
/// The windowed editor (editor_window.cpp, over specula::present::Window). Builds without the
/// present library give a run_window that says so (exit code 2).

#include "editor/core/editor_session.h"

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>

namespace specula::editor {

struct WindowRun {
  std::string script;                            ///< replayed first (empty: none)
  std::optional<std::uint64_t> frames;           ///< close after this many frames (none: on close)
  std::optional<std::filesystem::path> screenshot; ///< the last frame, PNG, when the window closes
  /// Dynamic resolution: the frame rate to hold by rendering below the window's size
  /// (ResolutionGovernor, at least a quarter of each side); 0: always the full size.
  double target_fps = 30.0;
};

/// Runs the interactive editor on the session until the window closes (or run.frames have been
/// shown). Input goes through WindowControls (window_controls.h). Returns the exit code.
int run_window(EditorSession& session, const WindowRun& run);

} // namespace specula::editor
