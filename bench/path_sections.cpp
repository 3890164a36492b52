// Path tracing: converged references, cached, and speed against error.
//
//   path-reference  renders (or finds) each scene's converged reference: MIS path tracing with
//                   --reference-spp samples per pixel, an EXR under --reference-dir (default
//                   <build>/references) named <scene>-<hash>.exr, the hash over the scene file's
//                   bytes and every setting the image depends on. Rendered once; later runs load
//                   it.
//   path-error      per scene × light sampling (BSDF only, light only, MIS): 1-spp frames
//                   accumulated (the mean of the frames is the estimate, as the progressive
//                   renderer shows it), and at 1, 2, 4, … --path-spp samples the wall time so far
//                   (tracing, accumulation, and for the denoised variant the à-trous filter of the
//                   mean) with RMSE and mean FLIP against the reference, raw and denoised; the
//                   log-log slope of RMSE against time; the target check (Cornell box frames/s at
//                   1 spp, FLIP after 1 s of accumulation with and without the denoiser). Writes
//                   path-error.md and one log-log PNG per scene under --out-dir.
//   path-cache      ray-cache cubes in path mode (texels averaging path samples): per scene of
//                   --path-cache-scenes (square images), uncached MIS frames accumulated for
//                   3 × --path-budget-ms set the target — their FLIP after --path-budget-ms —
//                   and each cached contender (lookup mode × resolution × --cache-refresh, its
//                   cubes empty at the start) accumulates until it reaches that FLIP: the
//                   equal-error time and its ratio to the budget, and the FLIP on the cached
//                   object's pixels and elsewhere. Writes path-cache.md and one FLIP-against-time
//                   PNG per scene under --out-dir.
//
// Frames are rendered with render_frame directly (the scene layer and tracer built by one tick of
// the schedule), so a frame's time is the integrator's, not the schedule's bookkeeping. The
// reference's seed differs from the measurement's: the two sample sets are independent, so the
// error measured is not shrunk by shared samples.

#include "bench_common.h"
#include "plot_png.h"

#include "specula/cache/ray_cache.h"
#include "specula/core/error.h"
#include "specula/image/denoise.h"
#include "specula/image/flip.h"
#include "specula/image/image_io.h"
#include "specula/image/metrics.h"
#include "specula/render/render_job.h"
#include "specula/scene/components.h"
#include "specula/scene/scene.h"
#include "specula/systems/schedule.h"
#include "specula/trace/render_frame.h"
#include "specula/trace/stats.h"

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>
#include <vector>

namespace specula::bench {
namespace {

namespace fs = std::filesystem;

/// The measurement's and the reference's sample sets (independent scrambles).
constexpr std::uint32_t kMeasureSeed = 1;
constexpr std::uint32_t kReferenceSeed = 0x5eed;
/// Samples per reference frame (a frame continues the previous one's sequence).
constexpr std::uint32_t kReferenceFrameSpp = 16;
/// Bumped when what a reference means changes (its settings, the estimator's definition), so old
/// files are not taken for new ones. Integrator bug fixes need `rm -r <build>/references`.
constexpr const char* kReferenceVersion = "specula-path-reference-1";

// --- Scenes ------------------------------------------------------------------------------------

/// Every path scene is measured at the Cornell box's bench size: size/2 × size·400/1024
/// (512×400 at the default --size 1024).
std::uint32_t path_width(const Options& o) { return std::max(16u, o.size / 2); }
std::uint32_t path_height(const Options& o) { return std::max(16u, o.size * 400 / 1024); }

/// One scene loaded, its scene layer and tracer built by one tick, rendered frame by frame with
/// render_frame.
class PathScene {
public:
  PathScene(const Options& o, const std::string& name, bool square = false)
      : name_(name), file_(fs::path(o.source_dir) / "samples/scenes" / (name + ".json")),
        scene_(load_scene(file_)), width_(path_width(o)),
        height_(square ? path_width(o) : path_height(o)) {
    RenderJob job;
    job.backend = "embree";
    job.settings.mode = TraceMode::Cast; // the tick only builds the layer and the tracer
    job.settings.threads = o.threads;
    job.settings.max_depth = scene_.settings.max_depth;
    job.settings.background = scene_.settings.background;
    job.image = Framebuffer(width_, height_);
    prepare_rendering(scene_.registry, std::move(job));
    Schedule schedule;
    schedule.tick(scene_.registry, 0.0);
    camera_ = *active_camera(scene_.registry);
    base_ = scene_.registry.resource<RenderJob>().settings;
    base_.mode = TraceMode::Path;
    base_.spp = 1;
  }

  [[nodiscard]] const std::string& name() const { return name_; }
  [[nodiscard]] const fs::path& file() const { return file_; }
  [[nodiscard]] std::uint32_t width() const { return width_; }
  [[nodiscard]] std::uint32_t height() const { return height_; }
  /// Path mode with the scene's depth and background, 1 spp, the job's threads.
  [[nodiscard]] TraceSettings settings(LightSampling sampling, std::uint32_t seed) const {
    TraceSettings s = base_;
    s.sampling = sampling;
    s.seed = seed;
    return s;
  }
  FrameStats render(const TraceSettings& s, Framebuffer& out, GuideBuffers* guides,
                    RadianceHook* hook = nullptr) {
    ecs::Registry& reg = scene_.registry;
    return render_frame(*reg.resource<ActiveTracer>().tracer, reg.resource<SceneLayer>(), camera_,
                        s, out, hook, guides);
  }
  /// A ray-cache store with the scene's cubes made (empty).
  std::shared_ptr<cache::RayCacheStore> make_store(const cache::CacheSettings& settings) {
    auto store = std::make_shared<cache::RayCacheStore>(settings);
    (void)store->invalidate(scene_.registry, scene_.registry.resource<SceneLayer>());
    return store;
  }
  /// Per pixel, whether its camera ray meets a cached entity first.
  [[nodiscard]] std::vector<std::uint8_t> cached_mask(const cache::RayCacheStore& store) {
    ecs::Registry& reg = scene_.registry;
    std::vector<std::uint32_t> instances;
    for (std::size_t i = 0; i < store.cube_count(); ++i)
      instances.push_back(store.cube(i).instance);
    const CameraRays rays(camera_, width_, height_, reg.resource<SceneLayer>().render_origin());
    std::vector<Ray> batch;
    for (std::uint32_t y = 0; y < height_; ++y)
      for (std::uint32_t x = 0; x < width_; ++x) {
        Ray r = rays.ray(x, y);
        r.tnear = 0.0f;
        r.tfar = std::numeric_limits<float>::infinity();
        batch.push_back(r);
      }
    std::vector<Hit> hits(batch.size());
    reg.resource<ActiveTracer>().tracer->intersect(batch, hits);
    std::vector<std::uint8_t> mask(hits.size());
    for (std::size_t i = 0; i < hits.size(); ++i)
      mask[i] = hits[i].hit() &&
                std::find(instances.begin(), instances.end(), hits[i].instance) != instances.end();
    return mask;
  }

private:
  std::string name_;
  fs::path file_;
  Scene scene_;
  Camera camera_;
  std::uint32_t width_, height_;
  TraceSettings base_;
};

/// The running mean of frames and of their guides (the denoiser's guides are the frames' mean
/// albedo and normal, and the mean depth of the samples that hit something).
class Accumulator {
public:
  Accumulator(std::uint32_t w, std::uint32_t h)
      : width_(w), height_(h), colour_(std::size_t(w) * h), albedo_(colour_.size()),
        normal_(colour_.size()), depth_(colour_.size()), hits_(colour_.size()) {}

  void add(const Framebuffer& frame, const GuideBuffers& guides) {
    const std::span<const vec3> c = frame.pixels();
    for (std::size_t i = 0; i < colour_.size(); ++i) {
      colour_[i] += dvec3(c[i]);
      albedo_[i] += guides.albedo[i];
      normal_[i] += guides.normal[i];
      if (std::isfinite(guides.depth[i])) {
        depth_[i] += guides.depth[i];
        ++hits_[i];
      }
    }
    if (frames_ == 0) moments_.reset(colour_.size());
    moments_.add(frame, guides);
    ++frames_;
  }
  /// The variance of each pixel's mean, for the variance-guided colour weight (empty before two
  /// frames).
  [[nodiscard]] std::vector<float> variance() const { return moments_.variance_of_mean(); }
  [[nodiscard]] Framebuffer mean() const {
    Framebuffer out(width_, height_);
    const double inv = 1.0 / double(std::max<std::uint32_t>(1, frames_));
    for (std::size_t i = 0; i < colour_.size(); ++i) out.pixels()[i] = vec3(colour_[i] * inv);
    return out;
  }
  [[nodiscard]] GuideBuffers guides() const {
    GuideBuffers g;
    g.resize(colour_.size());
    const float inv = 1.0f / float(std::max<std::uint32_t>(1, frames_));
    for (std::size_t i = 0; i < colour_.size(); ++i) {
      g.albedo[i] = albedo_[i] * inv;
      g.normal[i] = normal_[i] * inv;
      g.depth[i] =
          hits_[i] == 0 ? std::numeric_limits<float>::infinity() : depth_[i] / float(hits_[i]);
    }
    return g;
  }
  [[nodiscard]] std::uint32_t frames() const { return frames_; }

private:
  std::uint32_t width_, height_;
  std::vector<dvec3> colour_;
  std::vector<vec3> albedo_, normal_;
  std::vector<float> depth_;
  std::vector<std::uint32_t> hits_;
  LuminanceMoments moments_;
  std::uint32_t frames_ = 0;
};

// --- References --------------------------------------------------------------------------------

/// FNV-1a, 64 bits.
class Hash {
public:
  void bytes(const void* data, std::size_t n) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < n; ++i) h_ = (h_ ^ p[i]) * 0x100000001b3ull;
  }
  template <typename T>
  void value(const T& v) {
    bytes(&v, sizeof v);
  }
  [[nodiscard]] std::string hex() const {
    char buf[17];
    std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h_));
    return buf;
  }

private:
  std::uint64_t h_ = 0xcbf29ce484222325ull;
};

fs::path reference_dir(const Options& o) {
  return o.reference_dir.empty() ? fs::path(SPECULA_BINARY_DIR) / "references"
                                 : fs::path(o.reference_dir);
}

/// <dir>/<scene>-<hash>.exr, the hash over the scene file and what the image depends on.
fs::path reference_path(const Options& o, const PathScene& scene) {
  std::ifstream in(scene.file(), std::ios::binary);
  const std::string bytes{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  if (!in && !in.eof()) throw Error(scene.file().string(), "cannot read the scene file");
  Hash h;
  h.bytes(kReferenceVersion, std::char_traits<char>::length(kReferenceVersion));
  h.bytes(bytes.data(), bytes.size());
  const TraceSettings s = scene.settings(LightSampling::Mis, kReferenceSeed);
  h.value(scene.width());
  h.value(scene.height());
  h.value(s.max_depth);
  h.value(s.min_weight);
  h.value(o.reference_spp);
  h.value(kReferenceSeed);
  h.value(kReferenceFrameSpp);
  return reference_dir(o) / (scene.name() + "-" + h.hex() + ".exr");
}

/// The cached reference, rendered first when missing (MIS, kReferenceFrameSpp-sample frames).
Framebuffer reference(const Options& o, PathScene& scene, Report& out) {
  const fs::path path = reference_path(o, scene);
  if (fs::exists(path)) {
    Framebuffer image = read_exr(path);
    if (image.width() == scene.width() && image.height() == scene.height()) {
      out("- %s: reference %s (cached)\n", scene.name().c_str(), path.string().c_str());
      return image;
    }
  }
  fs::create_directories(path.parent_path());
  TraceSettings s = scene.settings(LightSampling::Mis, kReferenceSeed);
  s.spp = std::min(o.reference_spp, kReferenceFrameSpp);
  Framebuffer frame(scene.width(), scene.height());
  std::vector<dvec3> sum(frame.pixel_count());
  std::uint32_t done = 0;
  const double ms = time_ms([&] {
    while (done < o.reference_spp) {
      s.sample_offset = done;
      s.spp = std::min(s.spp, o.reference_spp - done);
      (void)scene.render(s, frame, nullptr);
      for (std::size_t i = 0; i < sum.size(); ++i)
        sum[i] += dvec3(frame.pixels()[i]) * double(s.spp);
      done += s.spp;
    }
  });
  Framebuffer image(scene.width(), scene.height());
  for (std::size_t i = 0; i < sum.size(); ++i)
    image.pixels()[i] = vec3(sum[i] / double(o.reference_spp));
  // Written under a temporary name and renamed, so a killed run leaves no half file behind.
  const fs::path partial = path.string() + ".partial";
  write_exr(image, partial);
  fs::rename(partial, path);
  out("- %s: reference %s rendered (%u spp, %.1f s on %u threads)\n", scene.name().c_str(),
      path.string().c_str(), o.reference_spp, ms / 1000.0, o.threads);
  return image;
}

// --- Measurements ------------------------------------------------------------------------------

struct Checkpoint {
  std::uint32_t spp = 0;
  double ms = 0.0;         ///< tracing + accumulation so far
  double denoise_ms = 0.0; ///< the à-trous filter of this checkpoint's mean
  double rmse = 0.0, flip = 0.0;
  double rmse_denoised = 0.0, flip_denoised = 0.0;
};

struct Run {
  LightSampling sampling = LightSampling::Mis;
  std::vector<Checkpoint> points;
  std::vector<double> frame_ms; ///< render_frame alone, per 1-spp frame
};

const char* sampling_label(LightSampling s) {
  switch (s) {
  case LightSampling::Bsdf:
    return "BSDF";
  case LightSampling::Light:
    return "light";
  case LightSampling::Mis:
    return "MIS";
  }
  return "?";
}

Rgb sampling_colour(LightSampling s, bool denoised) {
  switch (s) {
  case LightSampling::Bsdf:
    return denoised ? Rgb{120, 180, 230} : Rgb{31, 119, 180};
  case LightSampling::Light:
    return denoised ? Rgb{255, 190, 120} : Rgb{230, 110, 0};
  case LightSampling::Mis:
    return denoised ? Rgb{140, 210, 140} : Rgb{30, 140, 30};
  }
  return {};
}

DenoiseSettings denoise_settings(const Options& o) {
  DenoiseSettings d;
  d.threads = o.threads;
  if (!std::isnan(o.denoise_sigma_color)) d.sigma_color = float(o.denoise_sigma_color);
  if (!std::isnan(o.denoise_sigma_normal)) d.sigma_normal = float(o.denoise_sigma_normal);
  if (!std::isnan(o.denoise_sigma_depth)) d.sigma_depth = float(o.denoise_sigma_depth);
  if (o.denoise_levels > 0) d.iterations = o.denoise_levels;
  if (!std::isnan(o.denoise_sigma_variance)) d.sigma_variance = float(o.denoise_sigma_variance);
  return d;
}

/// `x` as printf's %g writes it.
std::string shortest(float x) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", double(x));
  return buf;
}

/// The mean's per-pixel variance for the denoiser: none (the fixed colour weight) with
/// --denoise-fixed.
std::vector<float> denoise_variance(const Options& o, const Accumulator& acc) {
  return o.denoise_fixed ? std::vector<float>{} : acc.variance();
}

/// Accumulates 1-spp frames up to `max_spp`, measuring at every power of two.
Run measure(const Options& o, PathScene& scene, const Framebuffer& ref, LightSampling sampling,
            std::uint32_t max_spp) {
  Run run;
  run.sampling = sampling;
  TraceSettings s = scene.settings(sampling, kMeasureSeed);
  Framebuffer frame(scene.width(), scene.height());
  GuideBuffers guides;
  Accumulator acc(scene.width(), scene.height());
  double elapsed = 0.0;
  std::uint32_t next = 1;
  for (std::uint32_t k = 0; k < max_spp; ++k) {
    s.sample_offset = k;
    Framebuffer mean(1, 1);
    const bool checkpoint = k + 1 == next || k + 1 == max_spp;
    elapsed += time_ms([&] {
      run.frame_ms.push_back(time_ms([&] { (void)scene.render(s, frame, &guides); }));
      acc.add(frame, guides);
      if (checkpoint) mean = acc.mean(); // what the display shows
    });
    if (!checkpoint) continue;
    next *= 2;
    Checkpoint c;
    c.spp = k + 1;
    c.ms = elapsed;
    Framebuffer denoised(1, 1);
    c.denoise_ms = time_ms([&] {
      atrous_denoise(mean, acc.guides(), denoise_settings(o), denoised, denoise_variance(o, acc));
    });
    c.rmse = rmse(ref, mean);
    c.flip = flip(ref, mean).mean;
    c.rmse_denoised = rmse(ref, denoised);
    c.flip_denoised = flip(ref, denoised).mean;
    run.points.push_back(c);
  }
  return run;
}

/// Least-squares slope of log y against log x.
double log_log_slope(const std::vector<std::pair<double, double>>& xy) {
  double n = 0, sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (const auto& [x, y] : xy) {
    if (!(x > 0.0 && y > 0.0)) continue;
    const double lx = std::log(x), ly = std::log(y);
    n += 1;
    sx += lx;
    sy += ly;
    sxx += lx * lx;
    sxy += lx * ly;
  }
  const double d = n * sxx - sx * sx;
  return n < 2 || d == 0.0 ? std::numeric_limits<double>::quiet_NaN() : (n * sxy - sx * sy) / d;
}

/// The spp of the first checkpoint from which on the denoised estimate is worse than the raw one
/// (RMSE), or 0 when it stays better throughout.
std::uint32_t bias_takes_over(const Run& r) {
  for (std::size_t i = 0; i < r.points.size(); ++i) {
    bool worse = true;
    for (std::size_t j = i; j < r.points.size(); ++j)
      worse = worse && r.points[j].rmse_denoised > r.points[j].rmse;
    if (worse) return r.points[i].spp;
  }
  return 0;
}

std::string fixed(double v, int digits) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

std::string sci(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3e", v);
  return buf;
}

void scene_table(Report& out, const std::vector<Run>& runs) {
  out("| spp |");
  for (const Run& r : runs)
    out(" %s ms | %s RMSE | %s FLIP | +à-trous RMSE | +à-trous FLIP |", sampling_label(r.sampling),
        sampling_label(r.sampling), sampling_label(r.sampling));
  out(" à-trous ms |\n|---:|");
  for (std::size_t i = 0; i < runs.size(); ++i) out("---:|---:|---:|---:|---:|");
  out("---:|\n");
  for (std::size_t p = 0; p < runs.front().points.size(); ++p) {
    out("| %u |", runs.front().points[p].spp);
    std::vector<double> dn;
    for (const Run& r : runs) {
      const Checkpoint& c = r.points[p];
      out(" %s | %s | %s | %s | %s |", fixed(c.ms, 1).c_str(), sci(c.rmse).c_str(),
          fixed(c.flip, 4).c_str(), sci(c.rmse_denoised).c_str(),
          fixed(c.flip_denoised, 4).c_str());
      dn.push_back(c.denoise_ms);
    }
    out(" %s |\n", fixed(median(dn), 1).c_str());
  }
}

void scene_plot(const std::vector<Run>& runs, const std::string& name, const fs::path& path) {
  Plot plot;
  plot.title = "PATH TRACING: RMSE AGAINST WALL TIME, " + name + " (LOG-LOG)";
  plot.x_label = "LOG10 WALL TIME (MS): TRACING + ACCUMULATION (+ A-TROUS)";
  plot.y_label = "LOG10 RMSE";
  plot.x_step = 0.5;
  plot.y_step = 0.5;
  double x_lo = 1e300, x_hi = -1e300;
  const Marker markers[] = {Marker::Circle, Marker::Square, Marker::TriangleUp};
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const Run& r = runs[i];
    for (const bool denoised : {false, true}) {
      PlotSeries series;
      series.colour = sampling_colour(r.sampling, denoised);
      series.marker = denoised ? Marker::Diamond : markers[i % 3];
      for (const Checkpoint& c : r.points) {
        const double t = denoised ? c.ms + c.denoise_ms : c.ms;
        const double e = denoised ? c.rmse_denoised : c.rmse;
        if (!(e > 0.0)) continue;
        series.points.emplace_back(std::log10(t), std::log10(e));
        x_lo = std::min(x_lo, std::log10(t));
        x_hi = std::max(x_hi, std::log10(t));
      }
      plot.series.push_back(series);
      plot.legend.push_back(
          {std::string(sampling_label(r.sampling)) + (denoised ? " + A-TROUS" : " RAW"),
           series.colour, series.marker});
    }
  }
  // The Monte Carlo slope, through MIS's last raw point.
  for (const Run& r : runs)
    if (r.sampling == LightSampling::Mis && !r.points.empty()) {
      const Checkpoint& c = r.points.back();
      const double x1 = std::log10(c.ms), y1 = std::log10(c.rmse);
      PlotSeries slope;
      slope.colour = {128, 128, 128};
      slope.marker = Marker::Plus;
      slope.points = {{x_lo, y1 + 0.5 * (x1 - x_lo)}, {x_hi, y1 - 0.5 * (x_hi - x1)}};
      plot.series.push_back(slope);
      plot.legend.push_back({"SLOPE -1/2 (MONTE CARLO)", slope.colour, slope.marker});
    }
  write_plot_png(plot, path);
}

/// Accumulates MIS frames until `budget_ms` of wall time have passed, then denoises once.
void target_check(const Options& o, PathScene& scene, const Framebuffer& ref,
                  const std::vector<double>& frame_ms, const fs::path& dir, Report& out) {
  TraceSettings s = scene.settings(LightSampling::Mis, kMeasureSeed);
  Framebuffer frame(scene.width(), scene.height());
  GuideBuffers guides;
  Accumulator acc(scene.width(), scene.height());
  double elapsed = 0.0;
  Framebuffer mean(1, 1);
  for (std::uint32_t k = 0; elapsed < o.path_budget_ms; ++k) {
    s.sample_offset = k;
    elapsed += time_ms([&] {
      (void)scene.render(s, frame, &guides);
      acc.add(frame, guides);
    });
  }
  elapsed += time_ms([&] { mean = acc.mean(); });
  Framebuffer denoised(1, 1);
  const GuideBuffers mean_guides = acc.guides();
  const double dn = time_ms([&] {
    atrous_denoise(mean, mean_guides, denoise_settings(o), denoised, denoise_variance(o, acc));
  });
  // The fixed colour weight on the same mean, for comparison.
  Framebuffer fixed_weight(1, 1);
  atrous_denoise(mean, mean_guides, denoise_settings(o), fixed_weight);
  const double fps = 1000.0 / median(frame_ms);
  const std::string stem = "path-" + scene.name() + "-";
  write_png(ref, dir / (stem + "reference.png"));
  write_png(mean, dir / (stem + "1s-raw.png"));
  write_png(denoised, dir / (stem + "1s-denoised.png"));
  out("\n**Target check, %s %ux%u, MIS, %u threads.** 1 spp per frame: median %.1f ms, **%.1f "
      "frames/s** (target ≥ 15). After %.0f ms of accumulation (%u spp): mean FLIP **%.4f with "
      "the à-trous denoiser** (%s colour weight; %.1f ms more; target ≤ 0.05), %.4f with the "
      "fixed colour σ, %.4f without; RMSE %.3e with, %.3e without.\n",
      scene.name().c_str(), scene.width(), scene.height(), o.threads, median(frame_ms), fps,
      elapsed, acc.frames(), flip(ref, denoised).mean,
      o.denoise_fixed ? "fixed" : "variance-guided", dn, flip(ref, fixed_weight).mean,
      flip(ref, mean).mean, rmse(ref, denoised), rmse(ref, mean));
  out("\n| reference | after 1 s, raw | after 1 s, à-trous |\n|---|---|---|\n| "
      "![](%sreference.png) "
      "| ![](%s1s-raw.png) | ![](%s1s-denoised.png) |\n",
      stem.c_str(), stem.c_str(), stem.c_str());
}

fs::path out_dir(const Options& o) {
  const fs::path dir =
      o.out_dir.empty() ? fs::path(o.source_dir) / "docs/path-report" : fs::path(o.out_dir);
  fs::create_directories(dir);
  return dir;
}

void path_reference(const Options& o) {
  Report out;
  out("\n## Path tracing: converged references (MIS, %u spp, %ux%u, %u threads)\n\n",
      o.reference_spp, path_width(o), path_height(o), o.threads);
  for (const std::string& name : split_list(o.path_scenes)) {
    PathScene scene(o, name);
    (void)reference(o, scene, out);
  }
}

void path_error(const Options& o) {
  Report out;
  const fs::path dir = out_dir(o);
  const DenoiseSettings d = denoise_settings(o);
  out("\n## Path tracing: speed against error (%ux%u, %u threads, 1 spp per frame up to %u spp)"
      "\n\n",
      path_width(o), path_height(o), o.threads, o.path_spp);
  out("Each variant accumulates 1-spp frames (render_frame with the sample offset advancing; the "
      "estimate is the mean of the frames). *ms*: wall time up to that sample count — tracing "
      "and accumulation (the guides' mean included); the à-trous columns add the filter's own "
      "time (last column). RMSE (linear) and mean FLIP against the cached %u-spp MIS reference "
      "(a different seed). À-trous: %u levels, σ normal %g, σ depth %g, on the mean's guides; "
      "colour weight %s.\n\n",
      o.reference_spp, d.iterations, double(d.sigma_normal), double(d.sigma_depth),
      o.denoise_fixed
          ? ("fixed, σ colour " + shortest(d.sigma_color) + " (halved per level)").c_str()
          : ("variance-guided from 2 spp on, σ_v " + shortest(d.sigma_variance) +
             " (the per-pixel variance of the mean; at 1 spp the fixed σ colour " +
             shortest(d.sigma_color) + ", halved per level)")
                .c_str());
  std::vector<std::string> summary_rows;
  for (const std::string& name : split_list(o.path_scenes)) {
    PathScene scene(o, name);
    const Framebuffer ref = reference(o, scene, out);
    std::vector<Run> runs;
    for (const LightSampling s : {LightSampling::Bsdf, LightSampling::Light, LightSampling::Mis})
      runs.push_back(measure(o, scene, ref, s, o.path_spp));
    out("\n### %s\n\n", name.c_str());
    scene_table(out, runs);
    std::string upper = name;
    for (char& c : upper) c = char(std::toupper(static_cast<unsigned char>(c)));
    const fs::path png = dir / ("path-error-" + name + ".png");
    scene_plot(runs, upper, png);
    out("\n![RMSE against time, %s](path-error-%s.png)\n", name.c_str(), name.c_str());
    for (const Run& r : runs) {
      std::vector<std::pair<double, double>> by_time, by_spp;
      for (const Checkpoint& c : r.points)
        if (c.spp >= 4) { // the first frames carry start-up costs (caches, page faults)
          by_time.emplace_back(c.ms, c.rmse);
          by_spp.emplace_back(double(c.spp), c.rmse);
        }
      const std::uint32_t over = bias_takes_over(r);
      char row[768];
      std::snprintf(row, sizeof row, "| %s | %s | %.1f | %.1f | %.3f | %.3f | %s | %s |\n",
                    name.c_str(), sampling_label(r.sampling), median(r.frame_ms),
                    1000.0 / median(r.frame_ms), log_log_slope(by_time), log_log_slope(by_spp),
                    over == 0 ? ("> " + std::to_string(r.points.back().spp)).c_str()
                              : std::to_string(over).c_str(),
                    sci(r.points.back().rmse).c_str());
      summary_rows.push_back(row);
    }
    if (name == "cornell_box")
      for (const Run& r : runs)
        if (r.sampling == LightSampling::Mis) target_check(o, scene, ref, r.frame_ms, dir, out);
  }
  out("\n### Summary\n\n*slope*: least-squares slope of log RMSE against log time (from 4 spp "
      "on; Monte Carlo: −0.5) and against log spp; *bias takes over*: the first sample count "
      "from which on the denoised RMSE stays above the raw one.\n\n");
  out("| scene | sampling | frame ms (1 spp, median) | frames/s | slope vs time | slope vs spp | "
      "bias takes over (spp) | raw RMSE at the end |\n|---|---|---:|---:|---:|---:|---:|---:|\n");
  for (const std::string& row : summary_rows) out("%s", row.c_str());
  out.save(dir / "path-error.md");
  out("\nWrote %s and path-error-*.png there.\n", (dir / "path-error.md").string().c_str());
}

// --- Path mode with ray-cache cubes ------------------------------------------------------------

/// One contender's accumulation: after every 1-spp frame, the wall time so far (tracing and
/// accumulation) and the mean's FLIP and RMSE against the reference.
struct CacheRun {
  std::string label;
  std::uint32_t resolution = 0, samples = 0;
  bool serve = false; ///< texels served lookups
  std::vector<double> ms, flip, rmse, frame_ms;
  /// Per frame: mean FLIP over the cached object's pixels and over the others.
  std::vector<double> flip_cached, flip_rest;
  CacheCounts last;
  double served = 0.0; ///< share of the lookups served, over the run
};

/// Accumulates MIS frames (cached when `settings` has a policy) until `until_ms` of wall time,
/// or, with a target, until the FLIP reaches it; FLIP is also split by `mask` (the pixels whose
/// camera ray meets a cached object).
CacheRun accumulate(PathScene& scene, const Framebuffer& ref, const cache::CacheSettings& settings,
                    const std::vector<std::uint8_t>& mask, double until_ms,
                    double target_flip = -1.0, double target_rmse = -1.0) {
  CacheRun run;
  TraceSettings s = scene.settings(LightSampling::Mis, kMeasureSeed);
  std::shared_ptr<cache::RayCacheStore> store;
  if (settings.policy != cache::CachePolicy::Off) store = scene.make_store(settings);
  Framebuffer frame(scene.width(), scene.height()), mean(scene.width(), scene.height());
  std::vector<dvec3> sum(frame.pixel_count(), dvec3(0.0));
  double elapsed = 0.0;
  std::uint64_t lookups = 0, hits = 0;
  for (std::uint32_t k = 0;; ++k) {
    s.sample_offset = k;
    elapsed += time_ms([&] {
      const double ms = time_ms([&] { (void)scene.render(s, frame, nullptr, store.get()); });
      run.frame_ms.push_back(ms);
      const double inv = 1.0 / double(k + 1);
      for (std::size_t i = 0; i < sum.size(); ++i) {
        sum[i] += dvec3(frame.pixels()[i]);
        mean.pixels()[i] = vec3(sum[i] * inv);
      }
    });
    if (store) {
      run.last = store->counts();
      lookups += run.last.lookups;
      hits += run.last.hits;
    }
    run.ms.push_back(elapsed);
    const FlipResult f = flip(ref, mean);
    run.flip.push_back(f.mean);
    double in = 0.0, out = 0.0;
    std::size_t n_in = 0;
    for (std::size_t i = 0; i < mask.size(); ++i) {
      (mask[i] != 0 ? in : out) += double(f.error_map[i]);
      n_in += mask[i];
    }
    run.flip_cached.push_back(n_in > 0 ? in / double(n_in) : 0.0);
    run.flip_rest.push_back(n_in < mask.size() ? out / double(mask.size() - n_in) : 0.0);
    run.rmse.push_back(rmse(ref, mean));
    if (elapsed >= until_ms) break;
    // With targets: until both errors have reached theirs (at least once).
    if (target_flip > 0.0 && std::ranges::min(run.flip) <= target_flip &&
        std::ranges::min(run.rmse) <= target_rmse)
      break;
  }
  run.served = lookups > 0 ? double(hits) / double(lookups) : 0.0;
  return run;
}

/// Where a run's FLIP (log-log interpolated between frames) first reaches `target`; NaN if it
/// never does.
/// When the error `series` (per frame, FLIP or RMSE) first reached `target` (log-log
/// interpolated between frames); NaN if it never did.
double time_to(const CacheRun& r, const std::vector<double>& series, double target) {
  for (std::size_t k = 0; k < series.size(); ++k) {
    if (series[k] > target) continue;
    if (k == 0) return r.ms[0];
    const double x0 = std::log(r.ms[k - 1]), x1 = std::log(r.ms[k]);
    const double y0 = std::log(series[k - 1]), y1 = std::log(series[k]), y = std::log(target);
    return std::exp(y1 == y0 ? x1 : x0 + (x1 - x0) * (y - y0) / (y1 - y0));
  }
  return std::numeric_limits<double>::quiet_NaN();
}

/// The error `series` at `ms` (log-log interpolated; the last frame's when the run is shorter).
double value_at(const CacheRun& r, const std::vector<double>& series, double ms) {
  for (std::size_t k = 0; k < r.ms.size(); ++k) {
    if (r.ms[k] < ms) continue;
    if (k == 0) return series[0];
    const double x0 = std::log(r.ms[k - 1]), x1 = std::log(r.ms[k]), x = std::log(ms);
    const double y0 = std::log(series[k - 1]), y1 = std::log(series[k]);
    return std::exp(y0 + (y1 - y0) * (x - x0) / (x1 - x0));
  }
  return series.back();
}
double flip_at(const CacheRun& r, double ms) { return value_at(r, r.flip, ms); }

void path_cache_plot(const std::vector<CacheRun>& runs, const std::string& name, double target,
                     const fs::path& path) {
  Plot plot;
  plot.title = "PATH MODE WITH RAY-CACHE PROBES, " + name;
  plot.x_label = "LOG10 WALL TIME (MS): TRACING + ACCUMULATION";
  plot.y_label = "LOG10 MEAN FLIP";
  plot.y_reference = std::log10(target);
  const Rgb colours[] = {{0, 0, 0},       {31, 119, 180}, {230, 110, 0}, {30, 140, 30},
                         {200, 40, 40},   {140, 90, 180}, {140, 86, 75}, {220, 110, 190},
                         {120, 120, 120}, {180, 180, 40}, {20, 190, 200}};
  const Marker markers[] = {Marker::Circle, Marker::Square, Marker::TriangleUp,  Marker::Diamond,
                            Marker::Cross,  Marker::Plus,   Marker::TriangleDown};
  for (std::size_t i = 0; i < runs.size(); ++i) {
    PlotSeries series;
    series.colour = colours[i % std::size(colours)];
    series.marker = markers[i % std::size(markers)];
    for (std::size_t k = 0; k < runs[i].ms.size(); ++k)
      if (runs[i].flip[k] > 0.0)
        series.points.emplace_back(std::log10(runs[i].ms[k]), std::log10(runs[i].flip[k]));
    plot.series.push_back(series);
    std::string text = runs[i].label;
    for (char& c : text)
      if (c == ',') c = ' ';
    plot.legend.push_back({text, series.colour, series.marker});
  }
  write_plot_png(plot, path);
}

void path_cache(const Options& o) {
  Report out;
  // Beside the other ray-cache reports.
  const fs::path dir =
      o.out_dir.empty() ? fs::path(o.source_dir) / "docs/cache-report" : fs::path(o.out_dir);
  fs::create_directories(dir);
  const double budget = o.path_budget_ms;
  out("\n## Path tracing with ray-cache cubes: equal-error time (%ux%u, %u threads)\n\n",
      path_width(o), path_width(o), o.threads);
  out("Uncached MIS path tracing accumulates 1-spp frames for %.0f ms of wall time (tracing and "
      "accumulation); its mean FLIP against the %u-spp reference after %.0f ms is the target. "
      "Each cached contender starts with empty cubes and accumulates until it reaches that FLIP "
      "(or %.0f ms). *texels serve* (`--cache-serve on`): a leaving ray is traced to its first "
      "hit, whose emission it takes; a texel whose probe belongs to the surface hit — a moving "
      "average of the radiance scattered from it, weight at least *samples* — gives the rest and "
      "the path ends there; about *refresh* of a texel's lookups a frame are traced on anyway, "
      "for the probe alone. *irradiance* (`--cache-irradiance on`, the default): every traced "
      "leaving ray's light also goes to a coarse probe of the light arriving at the object "
      "(*cells*² a face, a moving average per cell), whose order-2 spherical-harmonic "
      "irradiance lights the object's own diffuse lobe (no bounce sampled for it, no area-light "
      "sample). "
      "*equal-error time*: when it got there (log-log interpolated between frames); "
      "*speed-up*: %.0f ms over it; the same for the RMSE (runs go on until both are reached). *on "
      "the mirror / elsewhere*: the mean FLIP over the pixels "
      "whose camera ray meets the cached object, and over the others, at the frame that "
      "reached %.0f ms (or the last). The uncached run is repeated last, to show the machine's "
      "drift.\n\n",
      3.0 * budget, o.reference_spp, budget, 3.0 * budget, budget, budget);
  for (const std::string& name : split_list(o.path_cache_scenes)) {
    PathScene scene(o, name, true);
    const Framebuffer ref = reference(o, scene, out);
    std::vector<CacheRun> runs;
    cache::CacheSettings any;
    any.policy = cache::CachePolicy::On;
    const std::vector<std::uint8_t> mask = scene.cached_mask(*scene.make_store(any));
    const double coverage =
        double(std::count(mask.begin(), mask.end(), std::uint8_t{1})) / double(mask.size());
    CacheRun off = accumulate(scene, ref, cache::CacheSettings{}, mask, 3.0 * budget);
    off.label = "uncached";
    const double target = flip_at(off, budget);
    const double target_rmse = value_at(off, off.rmse, budget);
    runs.push_back(off);
    // Path mode's lookups test the surface hit instead of the parallax (tau and march behave as
    // direction there): what varies is the texel size and the refresh rate, and whether the
    // irradiance probe lights the object's diffuse lobe (its cells: min(faces, 16)² a face).
    struct Setting {
      bool serve, irradiance;
      std::uint32_t resolution, samples, refresh;
    };
    const Setting settings[] = {{false, true, 16, 4, 2}, {false, true, 8, 4, 2},
                                {true, false, 16, 4, 2}, {true, false, 32, 4, 2},
                                {true, false, 64, 4, 8}, {true, false, 128, 4, 2},
                                {true, true, 128, 4, 2}};
    for (const Setting& st : settings) {
      if (st.resolution > o.cache_max_resolution) continue;
      cache::CacheSettings cs;
      cs.policy = cache::CachePolicy::On;
      cs.resolution = st.resolution;
      cs.path_serve = st.serve;
      cs.path_irradiance = st.irradiance;
      cs.path_samples = st.samples;
      cs.path_refresh = st.refresh;
      CacheRun r = accumulate(scene, ref, cs, mask, 3.0 * budget, target, target_rmse);
      char label[128];
      if (!st.serve)
        std::snprintf(label, sizeof label, "irradiance only, %u² cells",
                      std::min(st.resolution, cache::kIncomingCells));
      else
        std::snprintf(label, sizeof label, "texels serve: faces %u, samples %u, refresh %u%s",
                      st.resolution, st.samples, st.refresh, st.irradiance ? " + irradiance" : "");
      r.label = label;
      r.resolution = st.resolution;
      r.samples = st.samples;
      r.serve = st.serve;
      runs.push_back(r);
    }
    CacheRun again = accumulate(scene, ref, cache::CacheSettings{}, mask, 3.0 * budget);
    again.label = "uncached again";
    runs.push_back(again);

    out("\n### %s\n\nThe cached mirror covers %.1f%% of the frame. Target: uncached FLIP "
        "after %.0f ms = %.4f (the repeated uncached run: %.4f).\n\n",
        name.c_str(), 100.0 * coverage, budget, target, flip_at(again, budget));
    out("| contender | frame ms (median) | frames in %.0f ms | FLIP after %.0f ms | on the mirror "
        "/ elsewhere | RMSE after %.0f ms | equal-error time (ms) | speed-up | equal-RMSE time "
        "(ms) | speed-up (RMSE) | lookups served | texels valid | memory |\n"
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        budget, budget, budget);
    for (const CacheRun& r : runs) {
      const double t = time_to(r, r.flip, target);
      const double t_rmse = time_to(r, r.rmse, target_rmse);
      std::size_t at = 0;
      while (at + 1 < r.ms.size() && r.ms[at] < budget) ++at;
      const bool cached = r.resolution != 0;
      char row[768];
      std::snprintf(
          row, sizeof row,
          "| %s | %.1f | %zu | %.4f | %.4f / %.4f | %.4f | %s | %s | %s | %s | %s | %s | %s |\n",
          r.label.c_str(), median(r.frame_ms), at + 1, flip_at(r, budget), r.flip_cached[at],
          r.flip_rest[at], r.rmse[at],
          std::isnan(t) ? ("not in " + fixed(r.ms.back(), 0)).c_str() : fixed(t, 0).c_str(),
          std::isnan(t) ? "—" : (fixed(budget / t, 2) + "×").c_str(),
          std::isnan(t_rmse) ? ("not in " + fixed(r.ms.back(), 0)).c_str()
                             : fixed(t_rmse, 0).c_str(),
          std::isnan(t_rmse) ? "—" : (fixed(budget / t_rmse, 2) + "×").c_str(),
          cached && r.serve ? (fixed(100.0 * r.served, 1) + "%").c_str() : "—",
          cached && r.serve
              ? (std::to_string(r.last.valid) + " / " + std::to_string(r.last.texels)).c_str()
              : "—",
          cached ? (fixed(double(r.last.memory_bytes) / 1024.0, 0) + " KiB").c_str() : "—");
      out("%s", row);
    }
    const fs::path png = dir / ("path-cache-" + name + ".png");
    std::string upper = name;
    for (char& c : upper) c = char(std::toupper(static_cast<unsigned char>(c)));
    path_cache_plot(runs, upper, target, png);
    out("\n![FLIP against time, %s](path-cache-%s.png)\n", name.c_str(), name.c_str());
  }
  out.save(dir / "path-cache.md");
  out("\nWrote %s.\n", (dir / "path-cache.md").string().c_str());
}

} // namespace

void section_path_reference(const Options& o) {
  try {
    path_reference(o);
  } catch (const UnavailableError& e) {
    std::printf("\npath-reference skipped: %s\n", e.what()); // a build without path mode
  }
}

void section_path_cache(const Options& o) {
  try {
    path_cache(o);
  } catch (const UnavailableError& e) {
    std::printf("\npath-cache skipped: %s\n", e.what());
  }
}

void section_path_error(const Options& o) {
  try {
    path_error(o);
  } catch (const UnavailableError& e) {
    std::printf("\npath-error skipped: %s\n", e.what());
  }
}

} // namespace specula::bench
