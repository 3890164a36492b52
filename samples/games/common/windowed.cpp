// The windowed front end: compiled only where specula::present exists
// (samples/games/CMakeLists.txt).
#include "front_end.h"

#include <specula/core/error.h>
#include <specula/image/image_io.h>
#include <specula/present/window.h>
#include <specula/render/resolution_governor.h>
#include <specula/systems/schedule.h>
#include <specula/trace/stats.h>

#include <GLFW/glfw3.h>
#include <imgui.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <utility>
#include <vector>

namespace specula::games {

namespace {

/// Arrows or WASD for the directions, and space.
GameInput game_input(const present::InputState& in) {
  const std::pair<Key, std::array<int, 2>> map[] = {{Key::Left, {GLFW_KEY_LEFT, GLFW_KEY_A}},
                                                    {Key::Right, {GLFW_KEY_RIGHT, GLFW_KEY_D}},
                                                    {Key::Up, {GLFW_KEY_UP, GLFW_KEY_W}},
                                                    {Key::Down, {GLFW_KEY_DOWN, GLFW_KEY_S}},
                                                    {Key::Space, {GLFW_KEY_SPACE, GLFW_KEY_SPACE}}};
  GameInput g;
  if (in.ui_wants_keyboard) return g;
  for (const auto& [key, codes] : map) {
    for (const int code : codes) {
      if (in.down[std::size_t(code)]) g.set_down(key);
      if (in.pressed[std::size_t(code)]) g.set_pressed(key);
    }
  }
  if (!in.ui_wants_mouse) {
    g.mouse_dx = float(in.mouse_dx);
    g.mouse_dy = float(in.mouse_dy);
  }
  return g;
}

} // namespace

int run_windowed(Game& game, const std::string& game_name, const WindowedOptions& options) {
  present::WindowSettings settings;
  settings.title = game_name;
  settings.width = options.width;
  settings.height = options.height;
  settings.ui = true;
  const std::unique_ptr<present::Window> window = present::Window::open(settings);
  RenderJob job = game.render_job(options.width, options.height);
  job.backend = options.backend;
  if (options.mode) job.settings.mode = *options.mode;
  // A Vulkan backend renders on the window's device and keeps its frames there: the window
  // draws them where they are (a CPU backend's are uploaded).
  job.gpu.device = window->context();
  prepare_rendering(game.registry(), std::move(job));
  Tracer& tracer = *game.registry().resource<ActiveTracer>().tracer;
  keep_frames_on_device(tracer, true); // false, nothing kept, for a CPU backend
  std::uint64_t in_place = 0;
  Schedule schedule;
  std::vector<GameInput> played;
  present::InputState input;
  std::uint64_t frame = 0;
  std::vector<double> frame_ms; // poll to poll: what the player sees
  std::vector<double> scales;
  // Path and shadow modes refine over frames at one size: no dynamic resolution there.
  const bool progressive =
      stochastic_mode(game.registry().resource<RenderJob>().settings.mode);
  ResolutionGovernor governor(options.target_fps > 0.0 && !progressive ? 1e3 / options.target_fps
                                                                       : 0.0);
  auto last = std::chrono::steady_clock::now();
  for (; (!options.frames || frame < *options.frames) && window->poll(input) &&
         !input.down[GLFW_KEY_ESCAPE];
       ++frame) {
    const auto now = std::chrono::steady_clock::now();
    if (frame > 0) {
      frame_ms.push_back(std::chrono::duration<double, std::milli>(now - last).count());
      // Dynamic resolution: the next frame at the governor's scale, shown scaled up.
      const auto [w, h] =
          ResolutionGovernor::scaled(options.width, options.height, governor.next(frame_ms.back()));
      Framebuffer& image = game.registry().resource<RenderJob>().image;
      if (image.width() != w || image.height() != h) image = Framebuffer(w, h);
    }
    scales.push_back(governor.scale());
    last = now;
    const GameInput g = options.input ? options.input->at(frame) : game_input(input);
    played.push_back(g);
    // Fixed dt, as the replay uses: a recording replays to the same state.
    game.step(kFrameDt, g);
    schedule.tick(game.registry(), kFrameDt);
    const RenderJob& done = game.registry().resource<RenderJob>();
    window->begin_ui();
    ImGui::SetNextWindowPos(ImVec2(8, 8));
    ImGui::Begin("HUD", nullptr, ImGuiWindowFlags_AlwaysAutoResize | ImGuiWindowFlags_NoDecoration);
    ImGui::TextUnformatted(game.hud_text().c_str());
    ImGui::Text("%.1f ms/frame, %s", done.last.ms, done.backend.c_str());
    ImGui::End();
    ImGui::Render();
    if (const gpu::DeviceFrame* shown = device_frame(tracer)) {
      window->present(*shown, ImGui::GetDrawData());
      ++in_place;
    } else {
      window->present(done.image, ImGui::GetDrawData());
    }
  }
  if (options.frames && !frame_ms.empty()) {
    const double ms = median(frame_ms);
    std::printf("%s: %llu frames shown at %ux%u, median %.2f ms per frame (%.1f frames/s), "
                "render scale median %.3f; presented in place from the device: %llu\n",
                game_name.c_str(), static_cast<unsigned long long>(frame), options.width,
                options.height, ms, 1e3 / ms, median(scales),
                static_cast<unsigned long long>(in_place));
  }
  Framebuffer& image = game.registry().resource<RenderJob>().image;
  if (device_frame(tracer) != nullptr) read_back_frame(tracer, image); // only now on the host
  if (options.out) write_png(image, *options.out);
  if (options.record) {
    std::ofstream f(*options.record, std::ios::binary);
    f << format_input_script(played);
    if (!f) throw Error(options.record->string(), "cannot write the recording");
    std::printf("%s: recorded %zu frames to %s\n", game_name.c_str(), played.size(),
                options.record->string().c_str());
  }
  return 0;
}

} // namespace specula::games
