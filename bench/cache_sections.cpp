// Ray-cache cubes (Ruff, Clua, Fernandes 2013): speed against error, and the paper's experiments.
//
//   cache        per scene × lookup mode × cube resolution × τ (+ auto, + prefill): frame ms after
//                the fill, speed-up against uncached tracing measured in the same run (the
//                contenders interleaved tick by tick), PSNR and FLIP against the uncached image of
//                the same frame, acceptance rate, memory. Markdown + a scatter plot (PSNR against
//                speed-up) under --out-dir.
//   cache-paper  Table I analogue (speed-up against the number of hidden spheres), Fig. 7
//                analogue (outdated texels before each frame of a nine-step camera pan), Fig. 1
//                analogue (error against cube resolution), and the frames a pan takes to fill 99%
//                of the texels it addresses.
//
// One loaded scene serves every contender: each contender owns a RayCacheStore (so its cube keeps
// its own fill), and before a tick the bench makes it the render job's hook and the RayCaches
// resource — what prepare_rendering does for `--cache on` — or clears both for uncached tracing.
// The scenes are static and the camera only moves in the pans, so no contender's cube is
// invalidated by another's frames.

#include "bench_common.h"
#include "plot_png.h"

#include "specula/cache/cube_map.h"
#include "specula/cache/ray_cache.h"
#include "specula/image/flip.h"
#include "specula/image/image_io.h"
#include "specula/image/metrics.h"
#include "specula/render/render_job.h"
#include "specula/scene/components.h"
#include "specula/scene/scene.h"
#include "specula/systems/schedule.h"

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

namespace specula::bench {
namespace {

namespace fs = std::filesystem;
using cache::CachePolicy;
using cache::CacheSettings;
using cache::LookupMode;


std::string db(double v) {
  if (std::isinf(v)) return "inf";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", v);
  return buf;
}

fs::path out_dir(const Options& o) {
  const fs::path dir = o.out_dir.empty() ? fs::path(o.source_dir) / "docs/cache-report"
                                         : fs::path(o.out_dir);
  fs::create_directories(dir);
  return dir;
}

fs::path scene_path(const Options& o, const std::string& name) {
  return fs::path(o.source_dir) / "samples/scenes" / (name + ".json");
}

// --- Contenders and the loaded scene -----------------------------------------------------------

/// Records which texels of the first cube the lookups address (the texel the direction picks,
/// what direction and tau look up), then forwards everything to the store.
class RecordingHook final : public RadianceHook {
public:
  explicit RecordingHook(std::shared_ptr<cache::RayCacheStore> store) : store_(std::move(store)) {}
  void begin_frame(std::uint32_t w, std::uint32_t h, TraceMode mode) override {
    store_->begin_frame(w, h, mode);
    instance_ = ~0u;
    if (store_->cube_count() == 0) return;
    const cache::CubeView c = store_->cube(0);
    instance_ = c.instance;
    if (c.resolution != resolution_) {
      resolution_ = c.resolution;
      addressed_.assign(std::size_t(cache::kFaceCount) * resolution_ * resolution_, 0);
    }
  }
  [[nodiscard]] bool wants_lookups() const override { return store_->wants_lookups(); }
  void lookup(std::span<const LeavingQuery> queries,
              std::span<CachedRadiance> answers) const override {
    {
      const std::lock_guard lock(mutex_);
      for (const LeavingQuery& q : queries)
        if (q.instance == instance_) addressed_[cache::texel_of(q.direction, resolution_)] = 1;
    }
    store_->lookup(queries, answers);
  }
  void leaving(std::span<const LeavingRadiance> rays) override { store_->leaving(rays); }
  void end_frame(double trace_ms, std::uint64_t rays) override { store_->end_frame(trace_ms, rays); }
  void report(CacheCounts& out) const override { store_->report(out); }
  /// 1 for every texel some lookup addressed since the resolution was set.
  [[nodiscard]] const std::vector<std::uint8_t>& addressed() const { return addressed_; }

private:
  std::shared_ptr<cache::RayCacheStore> store_;
  std::uint32_t instance_ = ~0u, resolution_ = 0;
  mutable std::mutex mutex_;
  mutable std::vector<std::uint8_t> addressed_;
};

struct Contender {
  std::string label; ///< e.g. "tau 256 τ=0.25°"
  std::string kind;  ///< off, cast, direction, tau, march, auto, prefill
  TraceMode mode = TraceMode::Whitted;
  CacheSettings settings; ///< policy Off: uncached
  std::shared_ptr<cache::RayCacheStore> store;
  std::shared_ptr<RadianceHook> hook; ///< the store, or a RecordingHook around it
  std::vector<double> ms, trace_ms, paired_off_ms;
  FrameStats last;
  Framebuffer image{1, 1};
  int settle_frames = 0; ///< auto: frames from the measured view until its cubes' modes held

  [[nodiscard]] bool cached() const { return settings.policy != CachePolicy::Off; }
  [[nodiscard]] double median_ms() const { return median(ms); }
  [[nodiscard]] double speedup() const { return median(paired_off_ms) / median(ms); }
};

Contender uncached(TraceMode mode = TraceMode::Whitted) {
  Contender c;
  c.label = mode == TraceMode::Cast ? "cast (primary rays only)" : "uncached";
  c.kind = mode == TraceMode::Cast ? "cast" : "off";
  c.mode = mode;
  return c;
}

Contender cached(LookupMode lookup, std::uint32_t resolution, float tau_deg = 0.5f,
                 CachePolicy policy = CachePolicy::On, bool prefill = false, bool record = false,
                 std::uint32_t fill_budget = 0, std::uint32_t fill_ahead = 0) {
  Contender c;
  c.settings.policy = policy;
  c.settings.lookup = lookup;
  c.settings.resolution = resolution;
  c.settings.tau_deg = tau_deg;
  c.settings.prefill = prefill;
  c.settings.fill_budget = fill_budget;
  c.settings.fill_ahead = fill_ahead;
  c.settings.max_error_db = 40.0;
  c.kind = policy == CachePolicy::Auto ? "auto" : prefill ? "prefill" : cache::lookup_mode_name(lookup);
  char buf[96];
  if (policy == CachePolicy::Auto)
    std::snprintf(buf, sizeof buf, "auto %u (40 dB)", resolution);
  else if (prefill)
    std::snprintf(buf, sizeof buf, "prefill %u (direction)", resolution);
  else if (lookup == LookupMode::Direction)
    std::snprintf(buf, sizeof buf, "direction %u", resolution);
  else
    std::snprintf(buf, sizeof buf, "%s %u τ=%g°", cache::lookup_mode_name(lookup), resolution,
                  double(tau_deg));
  c.label = buf;
  c.store = std::make_shared<cache::RayCacheStore>(c.settings);
  if (record)
    c.hook = std::make_shared<RecordingHook>(c.store);
  else
    c.hook = c.store;
  return c;
}

/// One scene loaded once, rendered by whichever contender is made current.
class Bench {
public:
  Bench(const fs::path& path, std::uint32_t size, std::uint32_t threads)
      : scene_(load_scene(path)) {
    RenderJob job;
    job.backend = "embree";
    job.settings.mode = TraceMode::Whitted;
    job.settings.threads = threads;
    job.settings.max_depth = scene_.settings.max_depth;
    job.settings.min_weight = 1.0f / 256.0f;
    job.settings.background = scene_.settings.background;
    job.image = Framebuffer(size, size);
    prepare_rendering(scene_.registry, std::move(job));
    start_ = *active_camera(scene_.registry);
    build_ms_ = time_ms([&] { schedule_.tick(scene_.registry, 0.0); });
  }

  /// Renders one frame as `c`; returns its wall-clock ms (the whole tick) and keeps its stats.
  double tick(Contender& c, bool keep_image = false) {
    ecs::Registry& reg = scene_.registry;
    RenderJob& job = reg.resource<RenderJob>();
    job.settings.mode = c.mode;
    job.cache = c.settings;
    job.hook = c.cached() ? c.hook : nullptr;
    reg.resource_or_default<cache::RayCaches>().store = c.cached() ? c.store : nullptr;
    const double ms = time_ms([&] { schedule_.tick(reg, 0.0); });
    c.last = reg.resource<RenderJob>().last;
    if (keep_image) c.image = reg.resource<RenderJob>().image;
    return ms;
  }

  /// Puts the camera `deg` degrees about the vertical axis through what it looks at (the front
  /// sphere's centre) from where the scene file puts it; 0: the scene's own camera.
  void orbit(double deg) {
    const float a = glm::radians(float(deg));
    const vec3 c(start_.look_at), d = vec3(start_.position) - c; // scenes near the origin
    const vec3 p = c + vec3(d.x * std::cos(a) + d.z * std::sin(a), d.y,
                            -d.x * std::sin(a) + d.z * std::cos(a));
    scene_.registry.view<Camera>().each([&](Camera& cam) { cam.position = p; });
  }
  [[nodiscard]] double build_ms() const { return build_ms_; }

private:
  Scene scene_;
  Schedule schedule_;
  Camera start_;
  double build_ms_ = 0.0;
};

/// Fills every cached contender with `warmup` frames while the camera orbits towards the
/// scene's own view (from −pan_deg in equal steps, the last one step short of it; pan_deg 0: all
/// from the scene's view), then, from the scene's view, `repetitions` rounds of (uncached,
/// contender) tick pairs; the last tick of each keeps its image (the same frame for all).
void measure(Bench& bench, Contender& off, std::vector<Contender>& cs, int warmup,
             int repetitions, double pan_deg) {
  for (Contender& c : cs)
    for (int f = 0; f < warmup; ++f) {
      bench.orbit(-pan_deg + pan_deg * f / warmup);
      (void)bench.tick(c);
    }
  bench.orbit(0.0);
  // Auto is measured where it settles: frames from the measured view until every cube's mode
  // has held for kSettled frames (longer than the policy waits before it retries a mode that
  // missed the error bound; at most kMaxSettle).
  constexpr int kSettled = 40, kMaxSettle = 200;
  for (Contender& c : cs) {
    if (c.settings.policy != CachePolicy::Auto) continue;
    std::string modes;
    int held = 0;
    while (held < kSettled && c.settle_frames < kMaxSettle) {
      (void)bench.tick(c);
      ++c.settle_frames;
      std::string now;
      for (const CubeReport& r : c.last.cache.cubes) now += r.mode + ",";
      held = now == modes ? held + 1 : 0;
      modes = now;
    }
  }
  (void)bench.tick(off);
  for (int r = 0; r < repetitions; ++r) {
    const bool last = r + 1 == repetitions;
    for (Contender& c : cs) {
      const double b = bench.tick(off, last);
      off.ms.push_back(b);
      off.trace_ms.push_back(off.last.trace_ms);
      c.paired_off_ms.push_back(b);
      c.ms.push_back(bench.tick(c, last));
      c.trace_ms.push_back(c.last.trace_ms);
    }
  }
}

std::uint64_t secondary(const RayCounts& r) {
  return r[RayKind::Reflection] + r[RayKind::Refraction];
}

double acceptance(const CacheCounts& k) {
  return k.lookups == 0 ? 0.0 : double(k.hits) / double(k.lookups);
}

std::string mib(std::uint64_t bytes) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f", double(bytes) / (1024.0 * 1024.0));
  return buf;
}

std::vector<std::uint32_t> resolutions(const Options& o, std::vector<std::uint32_t> all) {
  std::vector<std::uint32_t> out;
  for (const std::uint32_t r : all)
    if (r <= o.cache_max_resolution) out.push_back(r);
  if (out.empty()) out.push_back(std::min(all.front(), o.cache_max_resolution));
  return out;
}

std::uint32_t clamp_res(const Options& o, std::uint32_t r) { return std::min(r, o.cache_max_resolution); }

Rgb mode_colour(const std::string& kind) {
  if (kind == "direction") return {31, 119, 180};
  if (kind == "tau") return {255, 127, 14};
  if (kind == "march") return {44, 160, 44};
  if (kind == "auto") return {214, 39, 40};
  if (kind == "prefill") return {148, 103, 189};
  return {0, 0, 0};
}

constexpr Marker kSceneMarkers[] = {Marker::Circle, Marker::Square,  Marker::TriangleUp,
                                    Marker::Diamond, Marker::Cross,  Marker::Plus,
                                    Marker::TriangleDown};

// --- Table I analogue --------------------------------------------------------------------------

void table_one(const Options& o, Report& out) {
  const std::uint32_t res = clamp_res(o, 512);
  out("\n### Table I analogue: speed-up against the number of hidden spheres (direction mode, "
      "%u² cube faces, after the fill; %ux%u, %u threads)\n\n",
      res, o.size, o.size, o.threads);
  out("Whole frames are Specula's conventional ray tracing (the paper's Table II setting: primary "
      "rays traced too). The cube is filled while the camera orbits towards the measured view (see the `cache` section: %d frames from %g° away). The *hybrid* column estimates the paper's Table I setting (primary rays "
      "rasterised) by subtracting the same scene's cast-mode frame (primary rays and local "
      "shading only, measured in the same run) from both: (uncached − cast) / (cached − cast).\n\n",
      o.cache_frames, o.cache_fill_pan);
  out("| N | uncached ms (fps) | cached ms (fps) | speed-up | hybrid speed-up | cast ms | rays "
      "uncached | rays cached | acceptance | PSNR (dB) | FLIP |\n"
      "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  for (const int n : {0, 1, 2, 4, 8, 16, 32}) {
    Bench bench(scene_path(o, "mirror_spheres_" + std::to_string(n)), o.size, o.threads);
    Contender off = uncached();
    std::vector<Contender> cs;
    cs.push_back(cached(LookupMode::Direction, res));
    cs.push_back(uncached(TraceMode::Cast));
    measure(bench, off, cs, o.cache_frames, o.cache_repetitions, o.cache_fill_pan);
    const Contender& c = cs[0];
    const double cast = cs[1].median_ms();
    const double off_ms = median(c.paired_off_ms), c_ms = c.median_ms();
    out("| %d | %.1f (%.1f) | %.1f (%.1f) | %.2f | %.2f | %.1f | %llu | %llu | %.3f | %s | %.4f "
        "|\n",
        n, off_ms, 1000.0 / off_ms, c_ms, 1000.0 / c_ms, off_ms / c_ms,
        (off_ms - cast) / std::max(1e-3, c_ms - cast), cast,
        static_cast<unsigned long long>(off.last.rays.total()),
        static_cast<unsigned long long>(c.last.rays.total()), acceptance(c.last.cache),
        db(psnr(off.image, c.image)).c_str(), flip(off.image, c.image).mean);
  }
}

} // namespace

// --- Section `cache` ---------------------------------------------------------------------------

void section_cache(const Options& o) {
  Report out;
  const fs::path dir = out_dir(o);
  out("\n## Ray-cache cubes: speed against error (%ux%u, %u threads, %d fill frames, %d "
      "interleaved repetitions)\n\n",
      o.size, o.size, o.threads, o.cache_frames, o.cache_repetitions);
  out("Every cached contender is first filled with %d frames while the camera orbits about the "
      "front sphere towards the scene's view (from %g° away, in equal steps, the last one step "
      "short of it: so most texels were written from other viewpoints than the one measured, as "
      "when a camera moves); auto then renders from the scene's view until its cube's mode has "
      "held for 40 frames (longer than it waits before retrying a mode that missed the error "
      "bound; at most 200: it is measured where it settles); then, from the scene's view, each "
      "repetition renders an uncached frame and a cached frame back to back. Frame ms: the median whole tick (invalidation and "
      "prefill included); speed-up: the median of the uncached frames paired with it over its "
      "own median. PSNR and mean FLIP compare its last frame with the uncached frame of the same "
      "view. Acceptance: hits / lookups in the last frame (hits include tau/march answers that "
      "an occlusion ray confirms, which trade a reflection ray for a shadow-type ray). Secondary: "
      "reflection + refraction rays traced in the last frame; rays: all rays. Memory: the cube's "
      "texels.\n",
      o.cache_frames, o.cache_fill_pan);
  Plot plot;
  plot.title = "RAY-CACHE CUBES: SPEED-UP AGAINST PSNR (" + std::to_string(o.size) + "X" +
               std::to_string(o.size) + ")";
  plot.x_label = "PSNR AGAINST UNCACHED (DB, 80 AND ABOVE, IDENTICAL INCLUDED, AT THE RIGHT EDGE)";
  plot.x_min = 20.0;
  plot.x_max = 80.0;
  plot.y_label = "SPEED-UP";
  plot.y_reference = 1.0;
  const std::vector<std::string> scenes = {"mirror_spheres_0",       "mirror_spheres_8",
                                           "mirror_spheres_32",      "mirror_spheres_glass_32",
                                           "mirror_spheres_heavy_32", "mirror_spheres_distant_32"};
  for (const char* kind : {"direction", "tau", "march", "auto", "prefill"})
    plot.legend.push_back({kind, mode_colour(kind), Marker::Circle});
  plot.legend.push_back({"", {}, {}});
  for (std::size_t s = 0; s < scenes.size(); ++s)
    plot.legend.push_back({scenes[s].substr(std::string("mirror_spheres_").size()),
                           {60, 60, 60}, kSceneMarkers[s]});

  for (std::size_t s = 0; s < scenes.size(); ++s) {
    const std::string& name = scenes[s];
    Bench bench(scene_path(o, name), o.size, o.threads);
    Contender off = uncached();
    std::vector<Contender> cs;
    for (const std::uint32_t r : resolutions(o, {128, 256, 512}))
      cs.push_back(cached(LookupMode::Direction, r));
    for (const LookupMode m : {LookupMode::Tau, LookupMode::March})
      for (const std::uint32_t r : resolutions(o, {128, 256, 512}))
        for (const float tau : {0.25f, 1.0f}) cs.push_back(cached(m, r, tau));
    cs.push_back(cached(LookupMode::Direction, clamp_res(o, 512), 0.5f, CachePolicy::Auto));
    cs.push_back(cached(LookupMode::Direction, clamp_res(o, 512), 0.5f, CachePolicy::On, true));
    cs.push_back(cached(LookupMode::March, clamp_res(o, 512), 1.0f, CachePolicy::On, true));
    cs.back().kind = "march";
    cs.back().label = "march " + std::to_string(clamp_res(o, 512)) + " τ=1° + prefill";
    measure(bench, off, cs, o.cache_frames, o.cache_repetitions, o.cache_fill_pan);
    out("\n### %s (first frame with the build: %.0f ms; uncached median %.1f ms, %llu rays)\n\n",
        name.c_str(), bench.build_ms(), median(off.ms),
        static_cast<unsigned long long>(off.last.rays.total()));
    out("| contender | frame ms | of which tracing | speed-up | PSNR (dB) | mean FLIP | acceptance | rejected | "
        "secondary | rays | valid texels | memory (MiB) |\n"
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    out("| uncached | %.1f | %.1f | 1.00 | | | | | %llu | %llu | | |\n", median(off.ms),
        median(off.trace_ms),
        static_cast<unsigned long long>(secondary(off.last.rays)),
        static_cast<unsigned long long>(off.last.rays.total()));
    for (const Contender& c : cs) {
      const double p = psnr(off.image, c.image);
      const double f = flip(off.image, c.image).mean;
      const CacheCounts& k = c.last.cache;
      out("| %s | %.1f | %.1f | %.2f | %s | %.4f | %.3f | %llu | %llu | %llu | %llu / %llu | %s |\n",
          c.label.c_str(), c.median_ms(), median(c.trace_ms), c.speedup(), db(p).c_str(), f, acceptance(k),
          static_cast<unsigned long long>(k.rejected),
          static_cast<unsigned long long>(secondary(c.last.rays)),
          static_cast<unsigned long long>(c.last.rays.total()),
          static_cast<unsigned long long>(k.valid), static_cast<unsigned long long>(k.texels),
          mib(k.memory_bytes).c_str());
      plot.points.push_back({std::min(p, 80.0), c.speedup(), mode_colour(c.kind), kSceneMarkers[s]});
    }
    for (const Contender& c : cs)
      if (c.kind == "auto")
        for (const CubeReport& r : c.last.cache.cubes)
          out("\nauto, cube of entity %u: mode %s after %d frames from the measured view — %s "
              "(estimated PSNR %s dB).\n",
              r.entity, r.mode.c_str(), c.settle_frames, r.reason.c_str(),
              db(r.estimated_psnr_db).c_str());
  }
  if (o.sections_list.count("cache-paper") == 0) table_one(o, out);
  out.save(dir / "cache.md");
  write_plot_png(plot, dir / "cache-scatter.png");
  out("\nWrote %s and %s.\n", (dir / "cache.md").string().c_str(),
      (dir / "cache-scatter.png").string().c_str());
}

// --- Section `cache-paper` ---------------------------------------------------------------------

/// The texels a pan addresses at all: a recording pass over steps 0…steps with a direction-mode
/// cube of its own (1 per texel addressed), and how many.
template <typename Pan>
std::pair<std::vector<std::uint8_t>, std::uint64_t> visible_texels(Bench& bench,
                                                                   std::uint32_t res, int steps,
                                                                   Pan pan) {
  Contender probe = cached(LookupMode::Direction, res, 0.5f, CachePolicy::On, false, true);
  for (int k = 0; k <= steps; ++k) {
    pan(k);
    (void)bench.tick(probe);
  }
  std::vector<std::uint8_t> visible = static_cast<const RecordingHook&>(*probe.hook).addressed();
  std::uint64_t count = 0;
  for (const std::uint8_t v : visible) count += v;
  return {std::move(visible), count};
}

void section_cache_paper(const Options& o) {
  Report out;
  const fs::path dir = out_dir(o);
  out("\n## Ray-caching textures (Ruff, Clua, Fernandes 2013): the paper's experiments on Specula "
      "(%ux%u, %u threads)\n",
      o.size, o.size, o.threads);
  table_one(o, out);

  // Fig. 7: outdated texels before each frame of a pan of nine steps of 10/3° about the sphere.
  constexpr int kPanSteps = 9;
  constexpr double kStepDeg = 10.0 / 3.0;
  const std::vector<std::uint32_t> fig7_res = resolutions(o, {128, 256, 512});
  out("\n### Fig. 7 analogue: outdated texels of the front sphere's cube before each frame of a "
      "pan (mirror_spheres_32, direction mode, no fill budget)\n\n");
  out("The camera orbits the front sphere's centre about the vertical axis in %d steps of 10/3° "
      "(frame 1 at the scene's own camera, frame 10 at 30°). *of all*: outdated texels of the "
      "whole cube (the paper's measure); *of visible*: outdated among the texels some lookup "
      "addressed during the whole pan; the acceptance column is hits / lookups in that frame.\n\n",
      kPanSteps);
  Plot fig7;
  fig7.title = "FIG. 7 ANALOGUE: OUTDATED TEXELS BEFORE EACH FRAME (PAN OF 9 X 10/3 DEG)";
  fig7.x_label = "FRAME";
  fig7.x_min = 1.0;
  fig7.x_step = 1.0;
  fig7.y_label = "OUTDATED OF VISIBLE (%)";
  fig7.y_min = 0.0;
  fig7.y_max = 100.0;
  const Rgb res_colours[] = {{31, 119, 180}, {255, 127, 14}, {44, 160, 44}, {214, 39, 40}};
  std::string header = "| frame | angle |", rule = "|---:|---:|";
  std::vector<std::vector<std::string>> cells(kPanSteps + 1);
  for (std::size_t ri = 0; ri < fig7_res.size(); ++ri) {
    const std::uint32_t res = fig7_res[ri];
    Bench bench(scene_path(o, "mirror_spheres_32"), o.size, o.threads);
    auto pan = [&](int step) { bench.orbit(step * kStepDeg); };
    // The visible set: a recording pass over the whole pan with a cube of its own.
    const auto [visible, visible_count] = visible_texels(bench, res, kPanSteps, pan);
    // The measured pan, with a fresh cube.
    Contender c = cached(LookupMode::Direction, res);
    header += " " + std::to_string(res) + "²: outdated of all | of visible | acceptance |";
    rule += "---:|---:|---:|";
    PlotSeries series;
    series.colour = res_colours[ri % 4];
    series.marker = kSceneMarkers[ri];
    for (int k = 0; k <= kPanSteps; ++k) {
      pan(k);
      double of_all = 100.0, of_visible = 100.0;
      if (c.store->cube_count() > 0) {
        const cache::CubeView v = c.store->cube(0);
        std::uint64_t valid = 0, valid_visible = 0;
        for (std::size_t t = 0; t < v.texels.size(); ++t) {
          const bool ok = v.texels[t].valid();
          valid += ok;
          valid_visible += ok && t < visible.size() && visible[t];
        }
        of_all = 100.0 * double(v.texels.size() - valid) / double(v.texels.size());
        of_visible = visible_count == 0 ? 0.0
                                        : 100.0 * double(visible_count - valid_visible) /
                                              double(visible_count);
      }
      (void)bench.tick(c);
      char buf[128];
      std::snprintf(buf, sizeof buf, " %.1f%% | %.1f%% | %.3f |", of_all, of_visible,
                    acceptance(c.last.cache));
      cells[std::size_t(k)].push_back(buf);
      series.points.emplace_back(double(k + 1), of_visible);
    }
    fig7.series.push_back(series);
    char label[64];
    std::snprintf(label, sizeof label, "%u: %.1f%% VISIBLE", res,
                  100.0 * double(visible_count) / double(visible.size()));
    fig7.legend.push_back({label, series.colour, series.marker});
    out("- %u² faces: %llu of %zu texels (%.1f%%) addressed during the pan.\n", res,
        static_cast<unsigned long long>(visible_count), visible.size(),
        100.0 * double(visible_count) / double(visible.size()));
  }
  out("\n%s\n%s\n", header.c_str(), rule.c_str());
  for (int k = 0; k <= kPanSteps; ++k) {
    std::string row = "| " + std::to_string(k + 1) + " | ";
    char a[32];
    std::snprintf(a, sizeof a, "%.1f° |", k * kStepDeg);
    row += a;
    for (const std::string& s : cells[std::size_t(k)]) row += s;
    out("%s\n", row.c_str());
  }
  write_plot_png(fig7, dir / "cache-fig7.png");

  // Fill target: frames until 99% of the visible texels are valid, panning back and forth.
  {
    const std::uint32_t res = clamp_res(o, 512);
    out("\n### Fill: frames until 99%% of the visible texels are valid (mirror_spheres_32, "
        "%u² faces, %ux%u, panning 0°→30°→0°… in 10/3° steps)\n\n",
        res, o.size, o.size);
    out("*fill ahead K*: before each frame, up to K outdated texels traced from where the view "
        "would look them up, nearest (in rings of tiles) to the directions the frame before looked "
        "up (`--cache-fill-ahead`). *acceptance at frame 8*: hits / lookups of that frame alone "
        "(the reading of \"visible\" as what the current view looks up). *PSNR at frame 10*: "
        "against an uncached frame of the same view (30°), rendered right after it.\n\n");
    out("| fill budget (texels/frame) | fill ahead (texels/frame) | frames to 90%% "
        "| frames to 99%% | valid of visible after frame 1 | after frame 8 "
        "| acceptance at frame 8 | PSNR at frame 10 (dB) | mean frame ms (first 10) "
        "| texels filled ahead (a frame, first 10) |\n"
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    Bench bench(scene_path(o, "mirror_spheres_32"), o.size, o.threads);
    auto angle_of = [&](int frame) { // 0-based frame → ping-pong step 0..9..0
      const int period = 2 * kPanSteps;
      const int m = frame % period;
      return m <= kPanSteps ? m : period - m;
    };
    auto pan = [&](int step) { bench.orbit(step * kStepDeg); };
    const auto [visible, visible_count] = visible_texels(bench, res, kPanSteps, pan);
    const int max_frames = std::max(20, 6 * kPanSteps);
    struct Row {
      std::uint32_t budget, ahead;
    };
    const std::uint32_t cube_texels = 6 * res * res;
    for (const Row row : {Row{0, 0}, Row{16384, 0}, Row{4096, 0}, Row{0, cube_texels / 32},
                          Row{0, cube_texels / 16}, Row{0, cube_texels / 8}}) {
      Contender c = cached(LookupMode::Direction, res, 0.5f, CachePolicy::On, false, false,
                           row.budget, row.ahead);
      Contender off = uncached();
      int to90 = -1, to99 = -1;
      double first = 0.0, eighth = 0.0, accept8 = 0.0, psnr10 = 0.0, ms10 = 0.0;
      std::uint64_t ahead10 = 0;
      for (int f = 0; f < max_frames && (to99 < 0 || f < 10); ++f) {
        pan(angle_of(f));
        const double ms = bench.tick(c, f == 9);
        if (f < 10) {
          ms10 += ms / 10.0;
          ahead10 += c.last.cache.prefilled;
        }
        if (f == 7) accept8 = acceptance(c.last.cache);
        if (f == 9) {
          (void)bench.tick(off, true);
          psnr10 = psnr(off.image, c.image);
        }
        const cache::CubeView v = c.store->cube(0);
        std::uint64_t valid_visible = 0;
        for (std::size_t t = 0; t < v.texels.size() && t < visible.size(); ++t)
          valid_visible += visible[t] && v.texels[t].valid();
        const double frac = visible_count == 0 ? 1.0 : double(valid_visible) / double(visible_count);
        if (f == 0) first = frac;
        if (f == 7) eighth = frac;
        if (to90 < 0 && frac >= 0.90) to90 = f + 1;
        if (to99 < 0 && frac >= 0.99) to99 = f + 1;
      }
      out("| %s | %s | %s | %s | %.1f%% | %.2f%% | %.3f | %s | %.2f | %llu |\n",
          row.budget == 0 ? "no limit" : std::to_string(row.budget).c_str(),
          row.ahead == 0 ? "off" : std::to_string(row.ahead).c_str(),
          to90 < 0 ? ("> " + std::to_string(max_frames)).c_str() : std::to_string(to90).c_str(),
          to99 < 0 ? ("> " + std::to_string(max_frames)).c_str() : std::to_string(to99).c_str(),
          100.0 * first, 100.0 * eighth, accept8, db(psnr10).c_str(), ms10,
          static_cast<unsigned long long>(ahead10 / 10));
    }
    out("\nVisible: %llu of %zu texels (%.1f%%), those some lookup addressed during one pass of the "
        "pan.\n",
        static_cast<unsigned long long>(visible_count), visible.size(),
        100.0 * double(visible_count) / double(visible.size()));
  }

  // Fig. 1: error against cube resolution, direction mode.
  out("\n### Fig. 1 analogue: error against cube resolution (direction mode)\n\n");
  out("*static fill*: %d fill frames from the measured view itself (every pixel then reads a texel "
      "written from its own view: the error is only texel sharing); *pan fill*: %d fill frames "
      "orbiting towards it from %g° away (texels mostly written from other viewpoints: the "
      "parallax of direction-only lookups shows). Speed-up, acceptance and memory are the pan "
      "fill's.\n\n",
      o.cache_frames, o.cache_frames, o.cache_fill_pan);
  out("| scene | resolution | frame ms | speed-up | PSNR static fill (dB) | FLIP static | PSNR pan "
      "fill (dB) | FLIP pan | acceptance | memory (MiB) |\n"
      "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
  Plot fig1;
  fig1.title = "FIG. 1 ANALOGUE: PSNR AGAINST CUBE RESOLUTION (DIRECTION MODE)";
  fig1.x_label = "LOG2 OF THE CUBE FACE RESOLUTION (6: 64, 10: 1024)";
  fig1.x_step = 1.0;
  fig1.y_label = "PSNR (DB)";
  const std::vector<std::string> fig1_scenes = {"mirror_spheres_32", "mirror_spheres_glass_32",
                                                "mirror_spheres_distant_32"};
  for (std::size_t s = 0; s < fig1_scenes.size(); ++s) {
    const std::string& name = fig1_scenes[s];
    Bench bench(scene_path(o, name), o.size, o.threads);
    Contender off = uncached(), off_static = uncached();
    std::vector<Contender> cs, statics;
    for (const std::uint32_t r : resolutions(o, {64, 128, 256, 512, 1024})) {
      cs.push_back(cached(LookupMode::Direction, r));
      statics.push_back(cached(LookupMode::Direction, r));
    }
    measure(bench, off_static, statics, o.cache_frames, 1, 0.0);
    measure(bench, off, cs, o.cache_frames, o.cache_repetitions, o.cache_fill_pan);
    PlotSeries series, series_static;
    series.colour = series_static.colour = res_colours[s % 4];
    series.marker = kSceneMarkers[s];
    series_static.marker = kSceneMarkers[s + 3];
    for (std::size_t i = 0; i < cs.size(); ++i) {
      const Contender& c = cs[i];
      const double p = psnr(off.image, c.image);
      const double ps = psnr(off_static.image, statics[i].image);
      out("| %s | %u | %.1f | %.2f | %s | %.4f | %s | %.4f | %.3f | %s |\n", name.c_str(),
          c.settings.resolution, c.median_ms(), c.speedup(), db(ps).c_str(),
          flip(off_static.image, statics[i].image).mean, db(p).c_str(),
          flip(off.image, c.image).mean, acceptance(c.last.cache),
          mib(c.last.cache.memory_bytes).c_str());
      const double x = std::log2(double(c.settings.resolution));
      series.points.emplace_back(x, std::isinf(p) ? 99.0 : p);
      series_static.points.emplace_back(x, std::isinf(ps) ? 99.0 : ps);
    }
    if (s == 0 && !cs.empty()) {
      // The paper's close-ups: the middle of the image (the front sphere), uncached and cached.
      const std::uint32_t side = std::max(8u, o.size * 2 / 5), x0 = (o.size - side) / 2,
                          y0 = (o.size - side) / 2;
      auto crop = [&](const Framebuffer& img) {
        Framebuffer c(side, side);
        for (std::uint32_t y = 0; y < side; ++y)
          for (std::uint32_t x = 0; x < side; ++x) c.at(x, y) = img.at(x0 + x, y0 + y);
        return c;
      };
      write_png(crop(off.image), dir / "fig1-uncached.png");
      for (const Contender& c : cs)
        if (c.settings.resolution == 128 || c.settings.resolution == 512)
          write_png(crop(c.image), dir / ("fig1-direction-" + std::to_string(c.settings.resolution) + ".png"));
    }
    fig1.series.push_back(series);
    fig1.series.push_back(series_static);
    const std::string short_name = name.substr(std::string("mirror_spheres_").size());
    fig1.legend.push_back({short_name + " PAN FILL", series.colour, series.marker});
    fig1.legend.push_back({short_name + " STATIC", series.colour, series_static.marker});
  }
  write_plot_png(fig1, dir / "cache-fig1.png");
  out.save(dir / "cache-paper.md");
  out("\nWrote %s, cache-fig7.png, cache-fig1.png and fig1-*.png there.\n",
      (dir / "cache-paper.md").string().c_str());
}

} // namespace specula::bench
