#pragma once
/// \file
/// The windowed editor (editor_window.cpp, over specula::present::Window). Builds without the
/// present library give a run_window that says so (exit code 2).

#include "editor/core/editor_session.h"

#include <string>

namespace specula::editor {

/// Runs the interactive editor on the session until the window closes; replays `script` (if
/// not empty) first, through the same actions. Returns the process exit code.
int run_window(EditorSession& session, const std::string& script);

} // namespace specula::editor
