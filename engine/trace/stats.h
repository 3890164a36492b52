#pragma once
/// \file
/// Per-frame statistics written by `specula render --stats FILE.json` (docs/stats-format.md).
/// Other tools read these names: keep them.

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace specula {

/// Why a ray was traced: every secondary ray knows it (ray-cache cubes intercept reflection and
/// refraction rays that leave an object).
enum class RayKind : std::uint8_t { Primary = 0, Shadow = 1, Reflection = 2, Refraction = 3 };
inline constexpr int kRayKindCount = 4;
[[nodiscard]] const char* ray_kind_name(RayKind kind);

struct RayCounts {
  std::uint64_t count[kRayKindCount] = {};
  /// Secondary rays not traced because their pixel reached kMaxRaysPerPixel (not in total()).
  std::uint64_t dropped = 0;
  /// Radiance samples (pixels, or trace_radiance's rays) that came out Inf or NaN and were
  /// written as 0 instead (not in total()). Loaders bound intensities so that this stays 0: a
  /// non-zero count is a bug, reported rather than written into the image.
  std::uint64_t nonfinite = 0;
  [[nodiscard]] std::uint64_t& operator[](RayKind k) { return count[static_cast<int>(k)]; }
  [[nodiscard]] std::uint64_t operator[](RayKind k) const { return count[static_cast<int>(k)]; }
  [[nodiscard]] std::uint64_t total() const;
  RayCounts& operator+=(const RayCounts& o);
  friend bool operator==(const RayCounts&, const RayCounts&) = default;
};

/// One ray-cache cube's frame: its lookup mode and the auto policy's latest decision.
struct CubeReport {
  std::uint32_t entity = 0; ///< entity index of its owner
  std::uint32_t resolution = 0;
  std::string mode;   ///< lookup mode in use ("direction", "tau", "march"), or "off"
  std::string reason; ///< why (the policy's latest decision, in words)
  std::uint64_t lookups = 0;
  std::uint64_t hits = 0;      ///< served from the cube (not traced)
  std::uint64_t valid = 0;     ///< valid texels at frame end
  double estimated_psnr_db = 0.0; ///< from verification rays (auto; 0: not measured yet)
  double saved_ms = 0.0;          ///< estimated tracing time the cube saved this frame
  friend bool operator==(const CubeReport&, const CubeReport&) = default;
};

/// Ray-cache cubes in a frame (all zero when caching is off).
struct CacheCounts {
  std::uint64_t lookups = 0;
  std::uint64_t hits = 0;        ///< served from a cube, not traced
  std::uint64_t rejected = 0;    ///< valid texel, refused by the tau/march test or a blocked confirm
  std::uint64_t verified = 0;    ///< accepted, but traced to measure the error (auto)
  std::uint64_t written = 0;     ///< texels written at frame end from the frame's rays
  std::uint64_t prefilled = 0;   ///< traced from the cube centre (prefill, fill ahead)
  std::uint64_t texels = 0;      ///< in every cube
  std::uint64_t valid = 0;       ///< valid at frame end
  std::uint64_t invalidated = 0; ///< outdated by this frame's invalidation
  std::uint64_t flush_all = 0;   ///< what flushing every cube would have outdated instead
  std::uint64_t memory_bytes = 0;
  std::vector<CubeReport> cubes;
  friend bool operator==(const CacheCounts&, const CacheCounts&) = default;
};

/// The acceleration system's part of a frame: the tracer's structure update, whole and per step
/// (Tracer::update's TracerUpdateStats), and what it did.
struct AccelStats {
  double ms = 0.0;              ///< the whole update (acceleration_system)
  double static_build_ms = 0.0; ///< building the static structure
  double blas_build_ms = 0.0;   ///< building per-mesh structures
  double refit_ms = 0.0;        ///< refitting deformed meshes
  double restructure_ms = 0.0;  ///< rebuilding degraded subtrees
  double top_build_ms = 0.0;    ///< the top level over the instances
  std::uint32_t static_builds = 0;
  std::uint32_t blas_builds = 0;
  std::uint32_t refits = 0;
  std::uint32_t restructures = 0;
  /// Instances left out of the top level: singular transform or collapsed bounds (a scale of 0).
  std::uint32_t hidden_instances = 0;
  /// Triangles whose structure was built from scratch this frame (static structure, per-mesh
  /// structures, restructured subtrees), refitted, or left untouched (the rest the tracer holds).
  std::uint64_t triangles_rebuilt = 0;
  std::uint64_t triangles_refit = 0;
  std::uint64_t triangles_untouched = 0;
  friend bool operator==(const AccelStats&, const AccelStats&) = default;
};

/// The stages of a wavefront device frame (cast and Whitted; gpu::DeviceRenderer): eye rays, hybrid
/// mode's visibility pass, then per wave traversal (with its queue sizing), shading and shadow
/// rays, and after the last wave the fold of every pixel's tree.
enum class GpuStage : std::uint8_t { Eye, Visibility, Trace, Shade, Shadow, Fold };
inline constexpr int kGpuStageCount = 6;
[[nodiscard]] const char* gpu_stage_name(GpuStage stage);
/// Device milliseconds by GpuStage (timestamps around each dispatch).
using GpuStageTimes = std::array<double, kGpuStageCount>;

/// A frame on a device (the Vulkan backends): the tracer's counters after it. Absent (present
/// false) on CPU backends; the stats file then has no "gpu" object in the frame.
struct GpuFrameStats {
  bool present = false;
  std::uint64_t rays = 0;       ///< rays the kernels traced
  std::uint64_t resumed = 0;    ///< rays resumed after using up a dispatch's traversal budget
  std::uint64_t cut = 0;        ///< rays the driver cut off silently: must be 0
  std::uint64_t dispatches = 0; ///< traversal dispatches
  double gpu_ms = 0.0;          ///< device time of those dispatches (timestamps)
  /// Of gpu_ms, each stage's: wavefront cast and Whitted frames (all 0 for other frames, and in
  /// the file no "stages_ms").
  GpuStageTimes stage_ms{};
  /// Submits waited for in the frame (device frames: its uploads and read-backs included); each
  /// is a round trip between host and device.
  std::uint64_t submits = 0;
  friend bool operator==(const GpuFrameStats&, const GpuFrameStats&) = default;
};

/// Wall-clock milliseconds of each system of the tick (the schedule's FrameTimings, by name).
struct SystemTimes {
  double animation_ms = 0.0;
  double transform_ms = 0.0;
  double scene_layer_ms = 0.0;
  double acceleration_ms = 0.0;
  double cache_invalidation_ms = 0.0;
  double render_ms = 0.0;
  friend bool operator==(const SystemTimes&, const SystemTimes&) = default;
};

struct FrameStats {
  double time = 0.0;     ///< scene time the frame shows (seconds since the schedule started)
  double ms = 0.0;       ///< wall-clock time of the whole frame: every system of the tick
  double trace_ms = 0.0; ///< of which tracing the image (render_system)
  RayCounts rays;
  CacheCounts cache;
  AccelStats accel;
  SystemTimes systems;
  /// Path and shadow modes: samples per pixel in the image shown (this frame's included); 0 in
  /// the deterministic modes, which accumulate nothing.
  std::uint64_t accumulated_samples = 0;
  /// Path and shadow modes: the running mean was cleared before this frame (the first frame, or
  /// the scene, camera or settings changed).
  bool accumulation_restarted = false;
  double denoise_ms = 0.0; ///< of trace_ms, the denoiser's part (0: not denoised)
  GpuFrameStats gpu;
  friend bool operator==(const FrameStats&, const FrameStats&) = default;
};

/// The settings a run used, echoed into the stats file so results can be reproduced.
struct RunSettings {
  std::string scene;
  std::string backend;
  std::string mode;
  std::uint32_t width = 0;
  std::uint32_t height = 0;
  std::uint32_t frames = 1;
  std::uint32_t threads = 0;
  std::uint32_t max_depth = 5;
  std::uint32_t cache_resolution = 0; ///< cube face resolution for every cube (0: each its own)
  std::string cache_policy = "off";   ///< off | on | auto
  std::string cache_lookup = "direction";
  float cache_tau_deg = 0.5f;
  std::uint32_t cache_fill_budget = 0;
  bool cache_prefill = false;
  std::uint32_t cache_fill_ahead = 0; ///< --cache-fill-ahead (0: off)
  std::uint32_t cache_samples = 4; ///< path mode: sample weight a texel needs before it serves
  std::uint32_t cache_refresh = 2; ///< path mode: lookups a serving texel traces a frame
  bool cache_irradiance = true;    ///< path mode: the incoming-light probe lights diffuse lobes
  bool cache_serve = false;        ///< path mode: the texels' probes serve leaving rays
  double max_error_db = 40.0;
  // The stochastic modes (files from before them have none: readers take these defaults).
  std::uint32_t spp = 1;
  std::uint32_t shadow_samples = 1;
  std::string sampling = "mis"; ///< mis | bsdf | light
  std::uint32_t seed = 0;
  bool accumulate = true;
  bool denoise = false; ///< the denoiser's settings below apply only when set
  std::uint32_t denoise_iterations = 5;
  float denoise_sigma_color = 0.6f;
  float denoise_sigma_normal = 0.1f;
  float denoise_sigma_depth = 0.1f;
  float denoise_sigma_variance = 12.0f; ///< from the second accumulated frame on
  // The Vulkan backends' device and options (empty gpu_device: a CPU backend; files from before
  // the Vulkan path have none).
  std::string gpu_device = {};      ///< the device's name
  std::string gpu_device_type = {}; ///< "discrete GPU", "integrated GPU", "CPU (software)", ...
  std::string gpu_execution = "wavefront"; ///< wavefront | single kernel
  std::string gpu_primary = "trace";       ///< trace | raster (hybrid mode)
  bool gpu_device_frames = true;
  float grid_density = 4.0f; ///< vulkan-grid's cells per triangle
  // Animated rendering (issue 11; older files have none): the scene times of the first and the
  // last frame (`--time T0:T1`, or the fixed 1/60 s steps without it).
  double time0 = 0.0;
  double time1 = 0.0;
  friend bool operator==(const RunSettings&, const RunSettings&) = default;
};

struct RunStats {
  RunSettings settings;
  std::vector<FrameStats> frames;
  friend bool operator==(const RunStats&, const RunStats&) = default;
};

/// The median of the values (the mean of the middle two for an even count; 0 for none): what the
/// stats file's summary and `specula render` report.
[[nodiscard]] double median(std::vector<double> values);

/// JSON text of the stats (docs/stats-format.md): {"settings": {...}, "frames": [{"ms", "rays":
/// {"primary", "shadow", "reflection", "refraction"}, "mrays_per_s": {...}, "cache": {"lookups",
/// "hits"}, "accel": {...}}, ...], "summary": {...}}.
[[nodiscard]] std::string stats_to_json(const RunStats& stats);
/// Parses what stats_to_json writes (derived fields are recomputed, not read). Throws
/// specula::Error(name, field, ...) on malformed input.
[[nodiscard]] RunStats stats_from_json(const std::string& text, const std::string& name);
/// Writes stats_to_json to a file; throws specula::Error when it cannot.
void write_stats_file(const RunStats& stats, const std::filesystem::path& path);

} // namespace specula
