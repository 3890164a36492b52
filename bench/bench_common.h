#pragma once
// What every section of specula_bench shares: options, timing, test meshes and scenes.

#include "specula/geometry/triangle_mesh.h"
#include "specula/scene/scene.h"

#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

namespace specula::bench {

struct Options {
  std::uint32_t size = 1024;
  std::uint32_t threads = 2;
  int repetitions = 7;
  int frames = 10;
  int subdivisions = 4;
  /// Largest mesh of the build-scaling section, in triangles.
  std::uint32_t max_build_triangles = 1u << 20;
  /// The paper section's native backends trace single rays through the 4-wide BVHs (false: the
  /// binary trees, RenderJob::native_wide_bvh), to measure what the wide trees buy.
  bool native_wide_bvh = true;
  std::string sections = "primary,tiles,whitted,depth,build,refit,native,paper";
  /// `sections` split at commas (main fills it).
  std::set<std::string> sections_list;
  /// Where the cache sections write their Markdown and PNGs (empty: docs/cache-report in
  /// source_dir).
  std::string out_dir;
  /// Largest ray-cache cube face resolution the cache sections try (smaller runs for smoke tests).
  std::uint32_t cache_max_resolution = 1024;
  /// The cache sections fill their cubes while the camera orbits this many degrees towards the
  /// measured view (0: fill from the measured view itself).
  double cache_fill_pan = 30.0;
  /// The cache sections' fill frames and interleaved repetitions: --frames and --repetitions when
  /// given, otherwise these (smaller than the other sections' defaults, so that the full cache
  /// report stays near a quarter of an hour at 1024x1024 on 2 threads).
  int cache_frames = 3;
  int cache_repetitions = 3;
  std::string source_dir = SPECULA_SOURCE_DIR;
  /// The path sections' scenes (samples/scenes/NAME.json), comma-separated.
  std::string path_scenes = "cornell_box,area_lights";
  /// path-cache's scenes (square images, so the front mirror covers a third of the frame).
  std::string path_cache_scenes = "mirror_spheres_distant_32,mirror_spheres_hall_32";
  /// path-error accumulates 1-spp frames up to this many samples.
  std::uint32_t path_spp = 256;
  /// Samples per pixel of the converged references.
  std::uint32_t reference_spp = 4096;
  /// Where the references are cached (empty: BUILD_DIR/references).
  std::string reference_dir;
  /// The target check's accumulation budget (wall-clock ms).
  double path_budget_ms = 1000.0;
  /// The à-trous denoiser's settings in the path sections (NaN / 0: DenoiseSettings' defaults).
  double denoise_sigma_color = std::numeric_limits<double>::quiet_NaN();
  double denoise_sigma_normal = std::numeric_limits<double>::quiet_NaN();
  double denoise_sigma_depth = std::numeric_limits<double>::quiet_NaN();
  std::uint32_t denoise_levels = 0;
  double denoise_sigma_variance = std::numeric_limits<double>::quiet_NaN();
  /// The fixed colour weight (DenoiseSettings::sigma_color) instead of the variance-guided one.
  bool denoise_fixed = false;
  /// The dynamic section's scene files, comma-separated (empty: the dynamic_three_classes sample
  /// and its large variant). BART's kitchen.aff and robots.aff give the paper's Table 1.
  std::string dynamic_scenes;
};

/// The non-empty items of a comma-separated list (--path-scenes, --dynamic-scenes, ...).
std::vector<std::string> split_list(const std::string& list);

/// Wall-clock milliseconds of f().
double time_ms(const std::function<void()>& f);
/// Millions of rays per second.
inline double mrays(std::uint64_t rays, double ms) { return double(rays) / (ms * 1e3); }
/// `base`, Loop-subdivided `levels` times with OpenMesh (×4 triangles per level).
TriangleMesh subdivided(const TriangleMesh& base, int levels);
/// A scene holding one static mesh, with the default camera and light framing it.
Scene mesh_scene(const TriangleMesh& mesh, std::uint32_t size);
/// The Stanford bunny of samples/models.
TriangleMesh load_bunny(const Options& o);

// Sections measuring Specula's own structures (native_sections.cpp).
void section_build(const Options& o);
void section_refit(const Options& o);
void section_native(const Options& o);
void section_paper(const Options& o);

// Ray-cache cubes (cache_sections.cpp): speed against error, and the paper's experiments.
void section_cache(const Options& o);
void section_cache_paper(const Options& o);

// Path tracing (path_sections.cpp): cached converged references, speed against error.
void section_path_reference(const Options& o);
void section_path_error(const Options& o);
void section_path_cache(const Options& o);

// The Vulkan backends beside the CPU ones (gpu_sections.cpp): kernel styles, structures, grid
// resolution.
void section_gpu(const Options& o);
/// The gpu section's device list and traversal table alone (the lavapipe target).
void section_gpu_traversal(const Options& o);
// Ray-cache cubes on the device (gpu_sections.cpp; part of gpu, or alone as gpu-cache): the
// mirror-spheres scene's frames/s cached against uncached, with the cached frames' PSNR.
void section_gpu_cache(const Options& o);
// Path and shadow frames by execution style (gpu_sections.cpp; part of gpu, or alone as gpu-path).
void section_gpu_path(const Options& o);

// Animated scenes (dynamic_sections.cpp): acceleration update against frame time per backend,
// per-frame plots, and the paper's Table 1 grid (Markdown and PNGs under --out-dir, default
// docs/dynamic-report).
void section_dynamic(const Options& o);
// The editor's viewport frames and picking (editor_sections.cpp; builds with the editor only).
void section_editor(const Options& o);

/// A report section's Markdown: printed to stdout as it is written and kept to be saved.
class Report {
public:
  void operator()(const char* fmt, ...) __attribute__((format(printf, 2, 3))) {
    char buf[4096];
    va_list args;
    va_start(args, fmt);
    std::vsnprintf(buf, sizeof buf, fmt, args);
    va_end(args);
    std::fputs(buf, stdout);
    std::fflush(stdout);
    text_ += buf;
  }
  void save(const std::filesystem::path& path) const {
    std::ofstream out(path, std::ios::binary);
    out << text_;
    if (!out) throw std::runtime_error("cannot write the report " + path.string());
  }

private:
  std::string text_;
};

} // namespace specula::bench
