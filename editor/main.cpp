// The `specula` program: headless subcommands over the engine (info, render, compare). Bad input
// ends with a message naming the file and the problem and exit code 1; a feature this build lacks
// ends with exit code 2; a backend failing while rendering (a lost GPU) with exit code 3.

#include "commands.h"
#include "compare_command.h"
#include "specula/core/error.h"
#include "specula/core/memory_budget.h"
#include "specula/render/render_job.h"
#include "specula/render/tracer_factory.h"
#include "specula/scene/scene.h"

#include <CLI/CLI.hpp>

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <exception>
#include <iostream>
#include <string>
#include <vector>

namespace {

/// `auto` and every backend name any build knows (a missing one exits 2 with the reason).
std::vector<std::string> backend_choices() {
  std::vector<std::string> names = {"auto"};
  for (const std::string_view name : specula::backend_names()) names.emplace_back(name);
  return names;
}

/// The value, when the whole text is a finite decimal number ("12", "-0.5", "1e3"; not "0x10",
/// "inf", "nan" or " 12").
bool parse_number(const std::string& text, double& value) {
  if (text.empty() || text.find_first_not_of("0123456789+-.eE") != std::string::npos) return false;
  char* end = nullptr;
  errno = 0;
  value = std::strtod(text.c_str(), &end);
  return end == text.c_str() + text.size() && errno != ERANGE;
}

/// A whole number in [lo, hi], for ->transform (which may rewrite the text: "1e3" → "1000").
/// CLI11's Range says "not in range" for "abc" too; this tells a value that is not a number from
/// one out of range.
CLI::Validator whole_number(std::uint64_t lo, std::uint64_t hi) {
  const std::string range = std::to_string(lo) + " - " + std::to_string(hi);
  return CLI::Validator(
      [lo, hi, range](std::string& text) -> std::string {
        double value = 0.0;
        if (!parse_number(text, value))
          return "expected a number in [" + range + "], got '" + specula::printable(text, 40) + "'";
        if (value != std::floor(value) || value < double(lo) || value > double(hi))
          return "expected a whole number in [" + range + "], got " + text;
        text = std::to_string(static_cast<std::uint64_t>(value)); // "1e3" converts as 1000
        return {};
      },
      "in [" + range + "]");
}

/// Any finite number (range checks with a message of their own follow in the command).
CLI::Validator number() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        double value = 0.0;
        if (!parse_number(text, value))
          return "expected a number, got '" + specula::printable(text, 40) + "'";
        return {};
      },
      "");
}

/// One of `names`. CLI11's IsMember echoes the value in full before the list; this cuts it.
CLI::Validator one_of(std::vector<std::string> names) {
  std::string list;
  for (const std::string& name : names) list += (list.empty() ? "" : ", ") + name;
  return CLI::Validator(
      [names, list](std::string& text) -> std::string {
        if (std::find(names.begin(), names.end(), text) != names.end()) return {};
        return "expected one of " + list + ", got '" + specula::printable(text, 40) + "'";
      },
      "{" + list + "}");
}

/// A path: an empty one is a mistake (of quoting, usually), not "no file".
CLI::Validator non_empty_path() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        return text.empty() ? "expected a file path, got an empty string" : std::string();
      },
      "");
}

/// A size for --memory-limit.
CLI::Validator byte_size() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        if (specula::parse_byte_size(text)) return {};
        return "expected a size such as 512M or 4G, got '" + specula::printable(text, 40) + "'";
      },
      "SIZE");
}

} // namespace

int main(int argc, char** argv) {
  using namespace specula;
  CLI::App app{"Specula: real-time ray tracing engine module"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "specula 0.1.0");
  // Every parse error in the house style (main's catch below), input escaped and cut.
  app.failure_message([](const CLI::App*, const CLI::Error& e) {
    return "specula: error: " + printable(e.what(), 400) +
           "\nRun with --help for more information.\n";
  });

  cli::InfoOptions info;
  CLI::App* info_cmd = app.add_subcommand(
      "info", "Print a scene's entity, triangle, material and light counts and bounds; without a "
              "scene, the backends and Vulkan devices of this machine");
  info_cmd
      ->add_option("scene", info.scene,
                   "Scene (.json, .gltf, .glb) or mesh (.obj, .ply, .off, .stl)")
      ->check(non_empty_path());
  info_cmd->add_flag("--json", info.json, "Print the summary as JSON");

  cli::RenderOptions render;
  CLI::App* render_cmd = app.add_subcommand("render", "Trace frames of a scene");
  render_cmd
      ->add_option("scene", render.scene,
                   "Scene (.json, .gltf, .glb) or mesh (.obj, .ply, .off, .stl)")
      ->required()
      ->check(non_empty_path());
  render_cmd
      ->add_option("--backend", render.backend, "Tracing backend (auto: the best one available)")
      ->check(one_of(backend_choices()))
      ->capture_default_str();
  render_cmd
      ->add_option("--gpu-execution", render.gpu_execution,
                   "Vulkan backends: whole frames as a wavefront (one dispatch per stage, ray "
                   "queues) or as a single kernel")
      ->check(one_of({"wavefront", "single"}))
      ->capture_default_str();
  render_cmd
      ->add_option("--gpu-primary", render.gpu_primary,
                   "Vulkan backends: primary hits of device frames traced, or rasterised by a "
                   "graphics pipeline (raster: hybrid mode)")
      ->check(one_of({"trace", "raster"}))
      ->capture_default_str();
  render_cmd
      ->add_option("--gpu-frames", render.gpu_frames,
                   "Vulkan backends: render whole frames on the device where the mode has "
                   "kernels (off: the CPU integrators over GPU traversal)")
      ->check(one_of({"on", "off"}))
      ->capture_default_str();
  render_cmd
      ->add_option("--grid-density", render.grid_density,
                   "vulkan-grid: target grid cells per triangle, in (0, 64]")
      ->check(number())
      ->capture_default_str();
  render_cmd->add_option("--mode", render.mode, "Integrator")
      ->check(one_of({"cast", "whitted", "path", "shadow"}))
      ->capture_default_str();
  render_cmd->add_option("--spp", render.spp, "Path mode: samples per pixel per frame")
      ->transform(whole_number(1, kMaxSpp))
      ->capture_default_str();
  render_cmd
      ->add_option("--shadow-samples", render.shadow_samples,
                   "Shadow mode: area-light samples per pixel per frame")
      ->transform(whole_number(1, kMaxShadowSamples))
      ->capture_default_str();
  render_cmd
      ->add_option("--sampling", render.sampling,
                   "Path mode: how area lights are reached (multiple importance sampling, BSDF "
                   "sampling only, light sampling only)")
      ->check(one_of({"mis", "bsdf", "light"}))
      ->capture_default_str();
  render_cmd
      ->add_option("--seed", render.seed,
                   "Path and shadow modes: scrambles every pixel's sample sequence")
      ->transform(whole_number(0, UINT32_MAX))
      ->capture_default_str();
  render_cmd
      ->add_option("--accumulate", render.accumulate,
                   "Path and shadow modes: average frames while nothing changes (off: each "
                   "frame shown alone)")
      ->check(one_of({"on", "off"}))
      ->capture_default_str();
  render_cmd->add_flag("--denoise", render.denoise,
                       "Path and shadow modes: filter the image with the edge-aware à-trous "
                       "denoiser");
  render_cmd->add_option("--width", render.width, "Image width (default: the scene's)")
      ->transform(whole_number(1, kMaxImageSide));
  render_cmd->add_option("--height", render.height, "Image height (default: the scene's)")
      ->transform(whole_number(1, kMaxImageSide));
  render_cmd->add_option("--frames", render.frames, "Frames to trace")
      ->transform(whole_number(1, cli::kMaxFrames))
      ->capture_default_str();
  render_cmd->add_option("--time", render.time,
                         "Scene-time range T0:T1 in seconds: frame i shows T0 + i*(T1-T0)/(N-1) "
                         "(default: steps of 1/60 s)");
  render_cmd->add_option("--threads", render.threads, "Worker threads (0: all)")
      ->transform(whole_number(0, 1024))
      ->capture_default_str();
  render_cmd
      ->add_option("--cache", render.cache,
                   "Ray-cache cubes: off, on (always, in --cache-lookup mode), auto (only where "
                   "they save time within --max-error-db), or a face resolution (auto at it)")
      ->capture_default_str();
  render_cmd->add_option("--cache-lookup", render.cache_lookup, "How a cached texel is accepted")
      ->check(one_of({"direction", "tau", "march"}))
      ->capture_default_str();
  render_cmd
      ->add_option("--cache-tau", render.cache_tau_deg,
                   "Acceptance angle (degrees) of the tau and march lookups")
      ->check(number())
      ->capture_default_str();
  render_cmd
      ->add_option("--cache-resolution", render.cache_resolution,
                   "Face resolution of every cube (default: each entity's ray_cache)")
      ->transform(whole_number(1, 4096));
  render_cmd
      ->add_option("--cache-fill", render.cache_fill,
                   "At most this many texels written per frame (0: no limit)")
      ->transform(whole_number(0, UINT32_MAX))
      ->capture_default_str();
  render_cmd
      ->add_option("--cache-samples", render.cache_samples,
                   "Path mode: the (moving-average) sample weight a texel needs before it "
                   "serves lookups")
      ->transform(whole_number(1, 65536))
      ->capture_default_str();
  render_cmd
      ->add_option("--cache-serve", render.cache_serve,
                   "Path mode: the texels' per-surface probes serve leaving rays (on) or only "
                   "gather (off)")
      ->capture_default_str();
  render_cmd
      ->add_option("--cache-irradiance", render.cache_irradiance,
                   "Path mode: each cube's probe of the light arriving at its object lights the "
                   "object's diffuse lobe (on) or the lobe is sampled (off)")
      ->capture_default_str();
  render_cmd
      ->add_option("--cache-refresh", render.cache_refresh,
                   "Path mode: about this many lookups of a serving texel are traced a frame, "
                   "for its probe alone (the pixels take its mean)")
      ->transform(whole_number(1, 65536))
      ->capture_default_str();
  render_cmd->add_flag("--cache-prefill", render.cache_prefill,
                       "Trace every outdated texel from its cube's centre before each frame");
  render_cmd
      ->add_option("--cache-fill-ahead", render.cache_fill_ahead,
                   "Before each frame, trace up to this many outdated texels from their cube's "
                   "centre, nearest the directions the last frame looked up first (0: off)")
      ->transform(whole_number(0, UINT32_MAX))
      ->capture_default_str();
  render_cmd
      ->add_option("--max-error-db", render.max_error_db,
                   "--cache auto: the PSNR against uncached tracing it must keep")
      ->check(number())
      ->capture_default_str();
  render_cmd
      ->add_option("--out", render.out,
                   "Write the last frame: .png (sRGB, 8-bit) or .exr (linear float)")
      ->check(non_empty_path());
  render_cmd->add_option("--stats", render.stats, "Write per-frame statistics as JSON")
      ->check(non_empty_path());
  render_cmd
      ->add_option("--memory-limit", render.memory_limit,
                   "Refuse a render needing more memory than this, e.g. 8G (default: 3/4 of "
                   "physical memory)")
      ->check(byte_size());

  cli::CompareOptions compare;
  CLI::App* compare_cmd =
      app.add_subcommand("compare", "Compare two images: RMSE, PSNR and mean FLIP");
  compare_cmd->add_option("a", compare.a, "Reference image (.png or .exr)")
      ->required()
      ->check(non_empty_path());
  compare_cmd->add_option("b", compare.b, "Test image (.png or .exr)")
      ->required()
      ->check(non_empty_path());
  compare_cmd->add_option("--heatmap", compare.heatmap, "Write the FLIP error map as a magma .png")
      ->check(non_empty_path());
  compare_cmd
      ->add_option("--memory-limit", compare.memory_limit,
                   "Refuse a comparison needing more memory than this, e.g. 8G (default: 3/4 of "
                   "physical memory)")
      ->check(byte_size());
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
      return cli::run_render(render, std::cout, &std::cerr, isatty(STDERR_FILENO) == 1, &std::cerr);
    if (compare_cmd->parsed()) return cli::run_compare(compare, std::cout);
  } catch (const Error& e) {
    std::cerr << "specula: error: " << e.what() << "\n";
    return kExitBadInput;
  } catch (const UnavailableError& e) {
    std::cerr << "specula: not available: " << one_line(e.what()) << "\n";
    return kExitUnavailable;
  } catch (const cli::BackendFailure& e) {
    std::cerr << "specula: " << one_line(e.what()) << "\n";
    return cli::kExitBackendFailed;
  } catch (const std::bad_alloc&) {
    std::cerr << "specula: error: out of memory\n";
    return kExitBadInput;
  } catch (const std::exception& e) {
    std::cerr << "specula: internal error: " << one_line(e.what()) << "\n";
    return 3;
  }
  return 0;
}
