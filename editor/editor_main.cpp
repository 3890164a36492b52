// specula-editor SCENE [--headless] [--script FILE] [--backend B] [--mode M] [--size WxH]
//   [--depth N] [--cache off|on] [--cache-fill-ahead K] [--frames N] [--screenshot PNG]
//   [--screenshot-ui PNG]
// Windowed by default (editor_window.cpp, when this build has specula::present); --headless runs
// the same session and panels without a window. Windowed, --frames N closes the window after N
// frames and --screenshot writes the last one (--screenshot-ui: with the panels over it, as drawn;
// headless, drawn offscreen on any Vulkan device); --target-fps F (default 30, 0 off) renders below
// the window's size when frames take longer than 1/F s (dynamic resolution). Exit codes: 0 done, 1
// bad input or a failed script line (the message names file:line), 2 a feature this build or
// machine lacks.

#include "editor/core/editor_session.h"
#include "editor/core/panels.h"
#include "editor/core/script.h"
#include "editor/editor_window.h"
#include "specula/core/error.h"

#include <CLI/CLI.hpp>

#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <string>

namespace {

/// "WxH" → (W, H), each 1 … kMaxImageSide.
bool parse_size(const std::string& text, std::uint32_t& w, std::uint32_t& h) {
  unsigned long a = 0, b = 0;
  char tail = 0;
  if (std::sscanf(text.c_str(), "%lux%lu%c", &a, &b, &tail) != 2) return false;
  if (a < 1 || b < 1 || a > specula::kMaxImageSide || b > specula::kMaxImageSide) return false;
  w = std::uint32_t(a);
  h = std::uint32_t(b);
  return true;
}

} // namespace

int main(int argc, char** argv) {
  using namespace specula;
  CLI::App app{"Specula editor"};
  std::string scene, script, backend = "auto", mode = "whitted", size = "960x540", caches = "off",
                             screenshot, screenshot_ui;
  bool headless = false;
  std::optional<std::uint32_t> depth;
  std::optional<std::uint32_t> frames;
  std::uint32_t fill_ahead = 0;
  double target_fps = 30.0;
  app.add_option("scene", scene, "Scene file")->required();
  app.add_flag("--headless", headless, "No window: run the script (or --frames) and exit");
  app.add_option("--script", script, "Replay editor actions from FILE (editor/core/script.h)");
  app.add_option("--backend", backend, "Tracing backend (auto, native, embree, vulkan, ...)");
  app.add_option("--mode", mode, "cast, whitted, path or shadow");
  app.add_option("--size", size, "Viewport size WxH");
  app.add_option("--depth", depth, "Longest secondary ray chain (default: the scene's)");
  app.add_option("--cache", caches, "Ray-cache cubes: off, on or auto");
  app.add_option("--cache-fill-ahead", fill_ahead,
                 "Ray-cache cubes: texels traced before each frame around the directions the "
                 "last frame looked up, so an orbiting view finds them filled (0: off)")
      ->check(CLI::Range(0u, 0xffffffffu));
  app.add_option("--frames", frames, "Frames to render (headless, no script) or to show before closing (windowed)")
      ->check(CLI::Range(1u, 1000000u));
  app.add_option("--screenshot", screenshot, "Write the last frame to this PNG");
  app.add_option("--screenshot-ui", screenshot_ui,
                 "Write the whole editor as drawn (the last frame with the panels over it) to this "
                 "PNG");
  app.add_option("--target-fps", target_fps,
                 "Window: frame rate held by rendering below the window's size (0: full size)")
      ->check(CLI::Range(0.0, 1000.0));
  CLI11_PARSE(app, argc, argv);

  try {
    editor::ViewSettings view;
    view.backend = backend;
    const std::optional<TraceMode> m = parse_trace_mode(mode);
    if (!m) throw Error("--mode", "expected cast, whitted, path or shadow, got '" + mode + "'");
    view.mode = *m;
    view.max_depth = depth;
    if (!parse_size(size, view.width, view.height))
      throw Error("--size", "expected WxH with sides 1 to " + std::to_string(kMaxImageSide) +
                                ", got '" + size + "'");
    const std::optional<cache::CachePolicy> policy = cache::parse_cache_policy(caches);
    if (!policy) throw Error("--cache", "expected off, on or auto, got '" + caches + "'");
    view.cache.policy = *policy;
    view.cache.fill_ahead = fill_ahead;
    editor::EditorSession session(scene, view);
    session.tick(); // a first frame, so that clicks have something to pick in
    if (!headless) {
      editor::WindowRun run;
      run.script = script;
      run.frames = frames;
      run.target_fps = target_fps;
      if (!screenshot.empty()) run.screenshot = screenshot;
      if (!screenshot_ui.empty()) run.screenshot_ui = screenshot_ui;
      return editor::run_window(session, run);
    }
    // The panels run on a bare ImGui context, or drawn offscreen when the whole editor is wanted.
    std::optional<editor::HeadlessUi> bare;
    std::unique_ptr<editor::UiCapture> drawn;
    if (screenshot_ui.empty())
      bare.emplace(float(view.width), float(view.height));
    else
      drawn = editor::UiCapture::create(view.width, view.height);
    const auto ui_frame = [&] {
      if (drawn)
        drawn->frame(session);
      else
        bare->frame(session);
    };
    ui_frame();
    if (!script.empty())
      editor::run_script(session, script, ui_frame);
    else
      for (std::uint32_t i = 1; i < frames.value_or(1); ++i) {
        session.tick();
        ui_frame();
      }
    if (!screenshot.empty()) session.screenshot(screenshot);
    if (drawn) drawn->write(session, screenshot_ui);
    return 0;
  } catch (const UnavailableError& e) {
    std::cerr << "specula-editor: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "specula-editor: error: " << e.what() << "\n";
    return 1;
  }
}
