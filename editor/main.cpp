// The `specula` program: headless subcommands over the engine (info, render, compare). Bad input
// ends with a message naming the file and the problem and exit code 1; a feature this build lacks
// ends with exit code 2.

#include "commands.h"
#include "compare_command.h"
#include "specula/core/error.h"
#include "specula/render/tracer_factory.h"
#include "specula/scene/scene.h"

#include <CLI/CLI.hpp>

#include <unistd.h>

#include <exception>
#include <iostream>
#include <string>
#include <vector>

namespace {

/// `auto` and every backend name any build knows (a missing one exits 2 with the reason).
std::vector<std::string> backend_names() {
  std::vector<std::string> names = {"auto"};
  for (const specula::BackendInfo& b : specula::backends()) names.emplace_back(b.name);
  return names;
}

} // namespace

int main(int argc, char** argv) {
  using namespace specula;
  CLI::App app{"Specula: real-time ray tracing engine module"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "specula 0.1.0");

  cli::InfoOptions info;
  CLI::App* info_cmd =
      app.add_subcommand("info", "Print entity, triangle, material and light counts and bounds");
  info_cmd
      ->add_option("scene", info.scene,
                   "Scene (.json, .gltf, .glb) or mesh (.obj, .ply, .off, .stl)")
      ->required();
  info_cmd->add_flag("--json", info.json, "Print the summary as JSON");

  cli::RenderOptions render;
  CLI::App* render_cmd = app.add_subcommand("render", "Trace frames of a scene");
  render_cmd
      ->add_option("scene", render.scene,
                   "Scene (.json, .gltf, .glb) or mesh (.obj, .ply, .off, .stl)")
      ->required();
  render_cmd
      ->add_option("--backend", render.backend, "Tracing backend (auto: the best one available)")
      ->check(CLI::IsMember(backend_names()))
      ->capture_default_str();
  render_cmd->add_option("--mode", render.mode, "Integrator")
      ->check(CLI::IsMember({"cast", "whitted", "path", "shadow"}))
      ->capture_default_str();
  render_cmd->add_option("--width", render.width, "Image width (default: the scene's)")
      ->check(CLI::Range(1u, kMaxImageSide));
  render_cmd->add_option("--height", render.height, "Image height (default: the scene's)")
      ->check(CLI::Range(1u, kMaxImageSide));
  render_cmd->add_option("--frames", render.frames, "Frames to trace")
      ->check(CLI::Range(1u, 1000000u))
      ->capture_default_str();
  render_cmd->add_option("--threads", render.threads, "Worker threads (0: all)")
      ->check(CLI::Range(0u, 1024u))
      ->capture_default_str();
  render_cmd
      ->add_option("--cache", render.cache,
                   "Ray-cache cubes: off, on (always, in --cache-lookup mode), auto (only where "
                   "they save time within --max-error-db), or a face resolution (auto at it)")
      ->capture_default_str();
  render_cmd->add_option("--cache-lookup", render.cache_lookup, "How a cached texel is accepted")
      ->check(CLI::IsMember({"direction", "tau", "march"}))
      ->capture_default_str();
  render_cmd
      ->add_option("--cache-tau", render.cache_tau_deg,
                   "Acceptance angle (degrees) of the tau and march lookups")
      ->capture_default_str();
  render_cmd->add_option("--cache-resolution", render.cache_resolution,
                         "Face resolution of every cube (default: each entity's ray_cache)");
  render_cmd
      ->add_option("--cache-fill", render.cache_fill,
                   "At most this many texels written per frame (0: no limit)")
      ->capture_default_str();
  render_cmd->add_flag("--cache-prefill", render.cache_prefill,
                       "Trace every outdated texel from its cube's centre before each frame");
  render_cmd
      ->add_option("--max-error-db", render.max_error_db,
                   "--cache auto: the PSNR against uncached tracing it must keep")
      ->capture_default_str();
  render_cmd->add_option("--out", render.out, "Write the last frame as an sRGB PNG");
  render_cmd->add_option("--stats", render.stats, "Write per-frame statistics as JSON");

  cli::CompareOptions compare;
  CLI::App* compare_cmd =
      app.add_subcommand("compare", "Compare two images: RMSE, PSNR and mean FLIP");
  compare_cmd->add_option("a", compare.a, "Reference image (.png or .exr)")->required();
  compare_cmd->add_option("b", compare.b, "Test image (.png or .exr)")->required();
  compare_cmd->add_option("--heatmap", compare.heatmap, "Write the FLIP error map as a magma PNG");
  compare_cmd->add_flag("--json", compare.json, "Print the metrics as JSON");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : kExitBadInput;
  }

  try {
    if (info_cmd->parsed()) return cli::run_info(info, std::cout);
    if (render_cmd->parsed())
      return cli::run_render(render, std::cout, &std::cerr, isatty(STDERR_FILENO) == 1);
    if (compare_cmd->parsed()) return cli::run_compare(compare, std::cout);
  } catch (const Error& e) {
    std::cerr << "specula: error: " << e.what() << "\n";
    return kExitBadInput;
  } catch (const UnavailableError& e) {
    std::cerr << "specula: not available: " << e.what() << "\n";
    return kExitUnavailable;
  } catch (const std::bad_alloc&) {
    std::cerr << "specula: error: out of memory\n";
    return kExitBadInput;
  } catch (const std::exception& e) {
    std::cerr << "specula: internal error: " << e.what() << "\n";
    return 3;
  }
  return 0;
}
