#pragma once
/// \file
/// Presentation: shows the engine's frames to a person. A GLFW window presenting through a Vulkan
/// swapchain (Window), or an offscreen target of the same pipeline that is read back (Offscreen,
/// for headless runs, screenshots and tests). Both draw the frame scaled to the target and, when
/// given, Dear ImGui's draw data over it (the editor's panels, a game's HUD).
///
/// The frame is the engine's linear-radiance Framebuffer; it is tone mapped (clamp) and encoded
/// to sRGB on the way, the same way image/ writes PNGs, so a screenshot of the viewport with no
/// UI equals the PNG the CLI writes of the same frame.
///
/// Built into specula::present when Vulkan and GLFW are found (SPECULA_HAS_PRESENT is then
/// defined for users of the target). Runs on lavapipe under Xvfb.

#include "specula/image/framebuffer.h"

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

struct ImDrawData;

namespace specula::gpu {
class Context;
struct DeviceFrame;
} // namespace specula::gpu

namespace specula::present {

/// An 8-bit sRGB RGBA image read back from a target (row-major, top row first).
struct Rgba8Image {
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  std::vector<std::uint8_t> rgba; ///< width * height * 4 bytes
};

/// Input gathered by one Window::poll: held state and what happened since the previous poll.
/// Keys are GLFW key codes (GLFW_KEY_*), buttons GLFW mouse buttons (0 left, 1 right, 2 middle).
struct InputState {
  static constexpr int kKeyCount = 512;
  std::array<bool, kKeyCount> down{};     ///< held now
  std::array<bool, kKeyCount> pressed{};  ///< went down since the previous poll
  std::array<bool, 3> button_down{};
  std::array<bool, 3> button_pressed{};   ///< went down since the previous poll
  std::array<bool, 3> button_released{};
  double mouse_x = 0.0, mouse_y = 0.0;    ///< window pixels, origin top left
  double mouse_dx = 0.0, mouse_dy = 0.0;  ///< since the previous poll
  double scroll = 0.0;                    ///< vertical wheel steps since the previous poll
  bool close_requested = false;
  /// True while Dear ImGui wants the mouse / keyboard (a panel under the cursor, a text field):
  /// the application should then ignore them.
  bool ui_wants_mouse = false;
  bool ui_wants_keyboard = false;
};

struct WindowSettings {
  std::string title = "Specula";
  std::uint32_t width = 960;  ///< client area, pixels
  std::uint32_t height = 540;
  bool vsync = false;         ///< FIFO; off: MAILBOX or IMMEDIATE where offered
  /// Set up Dear ImGui (context, GLFW and Vulkan backends); the application then calls
  /// begin_ui() before its ImGui calls and passes ImGui::GetDrawData() to present().
  bool ui = false;
};

/// A window presenting through a Vulkan swapchain.
class Window {
public:
  /// Opens the window. Throws specula::UnavailableError with a one-line reason when there is no
  /// display, GLFW cannot start, or no Vulkan device can present to it.
  static std::unique_ptr<Window> open(const WindowSettings& settings);
  virtual ~Window() = default;

  /// Processes window events into `input`. Returns false once the window should close.
  virtual bool poll(InputState& input) = 0;
  /// Starts a Dear ImGui frame (ImGui::NewFrame with the backends'); only with settings.ui.
  virtual void begin_ui() = 0;
  /// Draws `frame` scaled to the client area (aspect kept, letterboxed), `ui` over it (null: no
  /// UI), and presents. Handles resizes and out-of-date swapchains itself. Returns once the
  /// drawing is submitted: the present call itself runs on a thread of its own while the caller
  /// goes on, and the next present() or read_back() waits for it (and throws what it failed with).
  virtual void present(const Framebuffer& frame, ImDrawData* ui) = 0;
  /// The same for a frame rendered on this window's device (a Vulkan tracer made on context(),
  /// its frames kept there: render/tracer_factory.h's keep_frames_on_device), used where it is:
  /// a kernel scales and encodes it into the image the UI is drawn over, no copy through the
  /// host. The bytes are those present(Framebuffer) shows for the frame read back. Throws
  /// std::invalid_argument for a frame of another device.
  virtual void present(const gpu::DeviceFrame& frame, ImDrawData* ui) = 0;
  /// The presenting device, to share: a Vulkan tracer made on it (GpuTracerOptions::device)
  /// renders frames present() can draw in place. Its queue is locked (Context::lock_queue)
  /// around every submission and present.
  [[nodiscard]] virtual std::shared_ptr<gpu::Context> context() const = 0;
  /// Asks for a new client area size (the window system may refuse or adjust it); the next
  /// present() after the resize lands draws at the new size.
  virtual void set_size(std::uint32_t width, std::uint32_t height) = 0;
  /// The client area now, in pixels.
  [[nodiscard]] virtual std::uint32_t width() const = 0;
  [[nodiscard]] virtual std::uint32_t height() const = 0;
  /// The Vulkan device presenting (e.g. "llvmpipe (LLVM 15.0.6, 256 bits)").
  [[nodiscard]] virtual std::string device_name() const = 0;
  /// The last presented image, read back (for --screenshot in windowed runs).
  [[nodiscard]] virtual Rgba8Image read_back() = 0;
};

struct OffscreenSettings {
  std::uint32_t width = 960;
  std::uint32_t height = 540;
  /// Set up a Dear ImGui context with the Vulkan backend (no window): the application sets
  /// io.DisplaySize, calls begin_ui() / ImGui::NewFrame and passes the draw data to render().
  bool ui = false;
};

/// The same drawing into an offscreen image on any Vulkan device (lavapipe included), no display
/// needed: headless editor runs, game replays, screenshots and tests.
class Offscreen {
public:
  /// Throws specula::UnavailableError with a one-line reason when no Vulkan device is present.
  static std::unique_ptr<Offscreen> create(const OffscreenSettings& settings);
  virtual ~Offscreen() = default;
  virtual void begin_ui() = 0;
  /// Draws `frame` and `ui` (as Window::present does) and returns the image.
  virtual Rgba8Image render(const Framebuffer& frame, ImDrawData* ui) = 0;
  /// The same for a frame on this target's device, used where it is (Window::present's).
  virtual Rgba8Image render(const gpu::DeviceFrame& frame, ImDrawData* ui) = 0;
  /// The device, to share with a tracer (Window::context).
  [[nodiscard]] virtual std::shared_ptr<gpu::Context> context() const = 0;
};

/// The CPU encoding present() applies, for comparing: clamp to [0, 1], sRGB, 8 bits, alpha 255;
/// scaled to fit width × height with letterboxing (black bars): bilinear (in linear colour) when
/// the frame is drawn larger than it is, nearest neighbour otherwise.
Rgba8Image encode_srgb8(const Framebuffer& frame, std::uint32_t width, std::uint32_t height);

} // namespace specula::present
