// The editor's viewport and picking (section "editor", not in the default list): frames of the
// Cornell box through the editor session at 960x540 (or --size, if smaller), Whitted, with and
// without the headless ImGui panels built; and picking — a camera ray through the active tracer
// per click — against the frame time, in one run.

#include "bench_common.h"
#include "editor/core/editor_session.h"
#include "editor/core/panels.h"
#include "specula/image/flip.h"
#include "specula/image/metrics.h"

#include <algorithm>
#include <cstdio>
#include <optional>
#include <random>
#include <vector>

namespace specula::bench {

namespace fs = std::filesystem;

void section_editor(const Options& o) {
  const std::uint32_t width = std::min(960u, o.size);
  const std::uint32_t height = std::max(1u, width * 9 / 16);
  const int frames = std::max(3, o.frames);
  std::printf("\n### Editor viewport and picking (Cornell box, %ux%u, Whitted, the scene's depth, "
              "%u threads, "
              "%d frames)\n\n",
              width, height, o.threads, frames);
  std::printf(
      "| backend | frame ms (median) | frames/s | with panels: frame ms | frames/s | "
      "pick ms (median / max of 1000) | pick / frame |\n|---|---:|---:|---:|---:|---:|---:|\n");
  // The Cornell box in the editor at the section's size, on `backend`.
  const auto cornell_session = [&](const char* backend) {
    editor::ViewSettings view;
    view.backend = backend;
    view.width = width;
    view.height = height;
    view.threads = o.threads;
    return editor::EditorSession(fs::path(o.source_dir) / "samples/scenes/cornell_box.json", view);
  };
  for (const char* backend : {"native", "embree"}) {
    if (!backend_info(backend).available) continue;
    editor::EditorSession session = cornell_session(backend);
    editor::HeadlessUi ui{float(width), float(height)};
    for (int i = 0; i < 3; ++i) session.tick(); // first build, caches warm
    std::vector<double> bare, with_ui, pick;
    for (int i = 0; i < frames; ++i) {
      bare.push_back(time_ms([&] { session.tick(); }));
      with_ui.push_back(time_ms([&] {
        session.tick();
        ui.frame(session);
      }));
    }
    std::mt19937 rng(7);
    std::uniform_int_distribution<std::uint32_t> x(0, width - 1), y(0, height - 1);
    for (int i = 0; i < 1000; ++i) {
      const std::uint32_t px = x(rng), py = y(rng);
      pick.push_back(time_ms([&] { (void)session.click(px, py); }));
    }
    const double frame = median(bare), framed = median(with_ui), picked = median(pick);
    std::printf("| %s | %.2f | %.1f | %.2f | %.1f | %.4f / %.4f | %.1e |\n", backend, frame,
                1e3 / frame, framed, 1e3 / framed, picked,
                *std::max_element(pick.begin(), pick.end()), picked / frame);
  }

  // Dynamic resolution (the windows' --target-fps): what a render scale saves, and what it costs
  // against the full-size frame once scaled up to the window as presentation does.
  const char* backend = backend_info("embree").available ? "embree" : "native";
  std::printf("\n#### Dynamic resolution: render scale against error (%s, %ux%u shown, %d frames "
              "each; the frame scaled up bilinearly as presentation does, and by nearest neighbour "
              "as it did before 2026-11-25)\n\n| scale | rendered | frame ms (median) | speed-up | "
              "PSNR dB | FLIP mean | nearest: PSNR dB | nearest: FLIP mean "
              "|\n|---:|---|---:|---:|---:|---:|---:|---:|\n",
              backend, width, height, frames);
  editor::EditorSession session = cornell_session(backend);
  double full_ms = 0.0;
  std::optional<Framebuffer> full;
  for (const float scale : {1.0f, 0.75f, 0.5f, 0.4375f, 0.34375f, 0.25f}) {
    session.set_render_scale(scale);
    for (int i = 0; i < 2; ++i) session.tick(); // the new size allocated
    std::vector<double> ms;
    for (int i = 0; i < frames; ++i) ms.push_back(time_ms([&] { session.tick(); }));
    const double m = median(ms);
    const Framebuffer shown = resample_bilinear(session.frame(), width, height);
    const Framebuffer blocky = resample_nearest(session.frame(), width, height);
    if (!full) {
      full = shown;
      full_ms = m;
    }
    std::printf("| %.3f | %ux%u | %.2f | %.2f | %.1f | %.4f | %.1f | %.4f |\n", double(scale),
                session.frame().width(), session.frame().height(), m, full_ms / m,
                psnr(*full, shown), flip(*full, shown).mean, psnr(*full, blocky),
                flip(*full, blocky).mean);
  }
}

} // namespace specula::bench
