// Harness for "load a JSON scene and render one frame": load_scene, then one tick of the frame
// schedule (animation, transforms, scene layer, acceleration structures, Whitted tracing) into a
// 16x16 image on the default backend, on one thread. The budget keeps each input fast: depth at
// most 3, and no render for scenes of more than kMaxFuzzTriangles triangles (loading them is the
// json harness's business). Checks the renderer's promise that every pixel is finite (issue 13:
// never write NaN silently).

#include "fuzz_support.h"

#include "specula/image/framebuffer.h"
#include "specula/render/render_job.h"
#include "specula/scene/scene.h"
#include "specula/systems/schedule.h"

#include <algorithm>
#include <cmath>

namespace {
constexpr std::uint64_t kMaxFuzzTriangles = 200'000;
constexpr std::uint32_t kMaxFuzzDepth = 3;
constexpr std::uint32_t kFuzzSide = 16;
} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::filesystem::path path = specula::fuzz::write_input({data, size}, "scene.json");
  specula::fuzz::expect_only_errors([&] {
    specula::Scene scene = specula::load_scene(path);
    if (specula::summarize(scene).triangles > kMaxFuzzTriangles) return;
    specula::RenderJob job;
    job.settings.mode = specula::TraceMode::Whitted;
    job.settings.max_depth = std::min(scene.settings.max_depth, kMaxFuzzDepth);
    job.settings.background = scene.settings.background;
    job.settings.threads = 1;
    job.image = specula::Framebuffer(kFuzzSide, kFuzzSide);
    specula::prepare_rendering(scene.registry, std::move(job));
    specula::Schedule schedule;
    schedule.tick(scene.registry, 1.0 / 60.0);
    for (const specula::vec3& p : scene.registry.resource<specula::RenderJob>().image.pixels())
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
        specula::fuzz::finding("the rendered image has a non-finite pixel");
  });
  return 0;
}
