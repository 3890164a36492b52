#pragma once
/// \file
/// Editor scripts (`specula-editor SCENE --script FILE`): one action per line, replayed through
/// the session's action layer, the same calls the mouse, keyboard and panels make. Blank lines
/// and `#` comments are skipped; an argument with spaces is written in double quotes.
///
///   frames N                 tick N frames (edits show in the next frame)
///   click X Y                select what pixel (X, Y) of the last frame shows (or nothing)
///   select NAME | deselect
///   drag AXIS DX DY          translate the selection along x|y|z by a screen vector (pixels)
///   rotate AXIS DX DY        rotate about x|y|z (kRotateRadiansPerPixel per pixel of DX)
///   scale AXIS DX DY         scale along x|y|z as drag moves
///   set PATH VALUE           a field of the selection (fields.h), e.g. set Transform.scale.y 2
///   add primitive KIND NAME | add mesh FILE NAME
///   delete | reparent NAME|none | undo | redo
///   save PATH | screenshot PATH   (the last frame, PNG)
///   backend NAME | mode cast|whitted|path|shadow | depth N | cache off|on
///   cache-view on|off        tint cached objects by their texels' state (cache_view.h)
///   orbit DX DY | frame-selected
///   expect selected NAME|none
///   expect PATH VALUE [TOLERANCE]   a field of the selection, numerically within TOLERANCE
///
/// Any failure throws specula::Error naming the script file and line.

#include "editor/core/editor_session.h"

#include <filesystem>
#include <functional>
#include <string>

namespace specula::editor {

/// Runs the script file; `on_frame` (if set) is called after every tick (the headless UI).
void run_script(EditorSession& session, const std::filesystem::path& file,
                const std::function<void()>& on_frame = {});

/// Runs script text; `name` is the file name messages use.
void run_script_text(EditorSession& session, const std::string& text, const std::string& name,
                     const std::function<void()>& on_frame = {});

} // namespace specula::editor
