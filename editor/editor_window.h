#pragma once
/// \file
/// The windowed editor (editor_window.cpp, over specula::present::Window). Builds without the
/// present library give a run_window that says so (exit code 2).

#include "editor/core/editor_session.h"

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

namespace specula::editor {

struct WindowRun {
  std::string script;                            ///< replayed first (empty: none)
  std::optional<std::uint64_t> frames;           ///< close after this many frames (none: on close)
  std::optional<std::filesystem::path> screenshot; ///< the last frame, PNG, when the window closes
  /// The whole window as last presented (the frame and the panels over it), PNG, when it closes.
  std::optional<std::filesystem::path> screenshot_ui;
  /// Dynamic resolution: the frame rate to hold by rendering below the window's size
  /// (ResolutionGovernor, at least a quarter of each side); 0: always the full size.
  double target_fps = 30.0;
};

/// Runs the interactive editor on the session until the window closes (or run.frames have been
/// shown). Input goes through WindowControls (window_controls.h). Returns the exit code.
int run_window(EditorSession& session, const WindowRun& run);

/// The editor as the window draws it, without a window: the panels of each frame (Dear ImGui
/// with its Vulkan backend, present::Offscreen) over the session's frame, for --headless
/// --screenshot-ui and the golden test of the whole editor. Frames advance ImGui's clock by a
/// fixed 1/60 s, so a replay draws the same panels every time.
class UiCapture {
public:
  /// Throws specula::UnavailableError when this build has no specula::present or there is no
  /// Vulkan device.
  static std::unique_ptr<UiCapture> create(std::uint32_t width, std::uint32_t height);
  virtual ~UiCapture() = default;
  /// One frame of the panels (they act on the session as in the window).
  virtual void frame(EditorSession& session) = 0;
  /// The session's current frame with the last frame's panels over it, as a PNG.
  virtual void write(const EditorSession& session, const std::filesystem::path& png) = 0;
};

} // namespace specula::editor
