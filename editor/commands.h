#pragma once
/// \file
/// The `specula` program's headless subcommands. Each returns the process exit code:
/// 0 success, 1 bad input (specula::kExitBadInput), 2 unavailable (specula::kExitUnavailable).

#include "specula/image/image_io.h"

#include <cstdint>
#include <iosfwd>
#include <optional>
#include <stdexcept>
#include <string>

namespace specula::cli {

/// Most frames one render may trace (each keeps its statistics in memory).
inline constexpr std::uint32_t kMaxFrames = 1000000;

struct InfoOptions {
  std::string scene; ///< empty: the backends and Vulkan devices of this machine instead
  bool json = false;
};

/// A tracing backend failed while rendering (a Vulkan call, a lost device): the run stops with
/// this message naming the backend and its device; exit code kExitBackendFailed.
class BackendFailure : public std::runtime_error {
public:
  using std::runtime_error::runtime_error;
};
inline constexpr int kExitBackendFailed = 3;

struct RenderOptions {
  std::string scene;
  std::string backend = "auto"; ///< auto | a backends() name (vulkan, embree, native, ...)
  std::string gpu_execution = "wavefront"; ///< wavefront | single (the Vulkan backends)
  std::string gpu_primary = "trace";       ///< trace | raster (hybrid mode, the Vulkan backends)
  std::string gpu_frames = "on";           ///< on | off: whole frames on the device
  float grid_density = 4.0f;               ///< vulkan-grid: cells per triangle
  std::string mode = "whitted"; ///< cast | whitted | path | shadow
  std::uint32_t width = 0;      ///< 0: the scene's settings
  std::uint32_t height = 0;     ///< 0: the scene's settings
  std::uint32_t frames = 1;
  /// "T0:T1": frame i shows scene time T0 + i·(T1−T0)/(frames−1) (T0 for one frame); empty: the
  /// scene file's range where it has one, else steps of 1/60 s from 1/60.
  std::string time;
  std::uint32_t threads = 0; ///< 0: every hardware thread
  std::string cache = "off"; ///< off | on | auto | a face resolution (auto at that resolution)
  std::string cache_lookup = "direction"; ///< direction | tau | march
  float cache_tau_deg = 0.5f;
  std::uint32_t cache_resolution = 0; ///< 0: each entity's own (or the one --cache gave)
  std::uint32_t cache_fill = 0;       ///< texels written per frame, 0: no limit
  bool cache_prefill = false;
  std::uint32_t cache_fill_ahead = 0; ///< texels traced from the centre ahead of the view
  std::uint32_t cache_samples = 4; ///< path mode: sample weight a texel needs before it serves
  std::uint32_t cache_refresh = 2; ///< path mode: lookups a serving texel traces a frame
  std::string cache_irradiance = "on"; ///< path mode: the incoming-light probe lights the lobe
  std::string cache_serve = "off";     ///< path mode: the texels' probes serve leaving rays
  double max_error_db = 40.0;
  std::uint32_t spp = 1;            ///< path: samples per pixel per frame
  std::uint32_t shadow_samples = 1; ///< shadow: area-light samples per pixel per frame
  std::string sampling = "mis";     ///< mis | bsdf | light
  std::uint32_t seed = 0;
  std::string accumulate = "on"; ///< on | off
  bool denoise = false;
  std::string out;           ///< .png or .exr path, empty: none
  std::string stats;         ///< stats JSON path, empty: none
  /// A size such as "4G" (core/memory_budget.h); empty: default_memory_budget().
  std::string memory_limit;
  /// Progress is shown once the render has run this long (seconds), on a terminal only.
  double progress_after_s = 1.0;
};

/// Prints the scene's summary, or without a scene the backends (availability, reasons) and the
/// Vulkan devices (name, type, the one the backend would choose).
int run_info(const InfoOptions& options, std::ostream& out);

/// A bound on the bytes a render of this size allocates beyond the scene, its acceleration
/// structures and ray-cache cubes: the framebuffer (12 bytes per pixel), writing the image in
/// `out`'s format (none: not written), every frame's statistics (and their JSON when `stats`),
/// and 64 MiB for the rest of the program.
/// In path and shadow modes (`stochastic`) it adds the accumulation's buffers (a double sum and
/// the frame: 36 bytes per pixel when `accumulate`) and, when `denoise`, the guides, the noisy
/// mean and two framebuffers for the denoiser's passes (64 bytes per pixel).
[[nodiscard]] std::uint64_t render_memory_bytes(std::uint32_t width, std::uint32_t height,
                                                std::uint32_t frames,
                                                std::optional<ImageFormat> out, bool stats,
                                                bool stochastic = false, bool accumulate = true,
                                                bool denoise = false);

/// Renders options.frames ticks of the scene. Before loading the scene, checks the options and
/// the output path (check_image_output_path); before allocating the framebuffer, checks
/// render_memory_bytes against the memory budget (exit 1 naming the scene when it does not fit).
/// With `--backend auto` and no real GPU, `notes` (nullptr: none) gets one line saying why a CPU
/// backend was chosen. A backend failing mid-render (a lost device) throws BackendFailure.
/// `progress` receives a one-line progress report (frames done, frames/s, time left), rewritten in
/// place and cleared at the end, once the render has run longer than options.progress_after_s and
/// when `progress_is_terminal`; pass nullptr for none.
int run_render(const RenderOptions& options, std::ostream& out, std::ostream* progress = nullptr,
               bool progress_is_terminal = false, std::ostream* notes = nullptr);

} // namespace specula::cli
