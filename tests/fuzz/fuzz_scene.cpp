// Harness for the scene readers as `specula info` runs them: load_scene (the format's reader,
// then the hierarchy, kinematics and defaults common to every format) and summarize.
// SPECULA_FUZZ_FILE names the scratch file, and so the format: scene.json, scene.gltf, scene.glb.

#include "fuzz_support.h"

#include "specula/scene/scene.h"

#include <cmath>

#ifndef SPECULA_FUZZ_FILE
#error "define SPECULA_FUZZ_FILE (e.g. \"scene.json\")"
#endif

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::filesystem::path path = specula::fuzz::write_input({data, size}, SPECULA_FUZZ_FILE);
  specula::fuzz::expect_only_errors([&] {
    specula::Scene scene = specula::load_scene(path);
    const specula::SceneSummary summary = specula::summarize(scene);
    // load_scene adds a camera and a light when the file has none.
    if (summary.cameras == 0 || summary.lights == 0)
      specula::fuzz::finding("load_scene returned a scene without a camera or a light");
  });
  return 0;
}
