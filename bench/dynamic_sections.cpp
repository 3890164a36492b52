// Animated scenes (issue 11): the acceleration-structure update against the frame, per backend,
// on samples/scenes/dynamic_three_classes.json and a larger variant built here (or the scene files
// of --dynamic-scenes: BART's kitchen.aff and robots.aff where they are at hand), with per-frame
// plots; and the real-time ray tracer paper's Table 1 grid (BVH only against kd-tree + BVH, per
// effect) on the same scenes.

#include "bench_common.h"
#include "plot_png.h"
#include "specula/geometry/primitives.h"
#include "specula/render/render_job.h"
#include "specula/render/tracer_factory.h"
#include "specula/scene/components.h"
#include "specula/systems/schedule.h"
#include "specula/trace/stats.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace specula::bench {
namespace {

namespace fs = std::filesystem;

constexpr double kDuration = 4.0; // the sample's animations loop over 4 s

Scene sample(const Options& o) {
  return load_scene(fs::path(o.source_dir) / "samples/scenes/dynamic_three_classes.json");
}

/// The sample plus a static statue (the bunny, Loop-subdivided twice: 57,760 triangles) and a
/// free, wobbling sphere of 16,384 triangles: about 76,000 triangles, 17,000 of them deforming.
Scene large(const Options& o) {
  Scene scene = sample(o);
  ecs::Registry& reg = scene.registry;
  TriangleMesh bunny = subdivided(load_bunny(o), 2);
  const Aabb bb = bunny.bounds();
  const float scale = 1.6f / bb.extent().y;
  ecs::Entity e = reg.create();
  Transform t;
  t.translation = vec3(-bb.center().x, -bb.min.y, -bb.center().z) * scale + vec3(-3, 0, -2.5);
  t.scale = vec3(scale);
  reg.emplace<Transform>(e, t);
  reg.emplace<Mesh>(e, Mesh{std::make_shared<const TriangleMesh>(std::move(bunny)), {}, {}, 0});
  reg.emplace<Material>(e, Material{});
  reg.emplace<Kinematics>(e, Kinematics{Kinematics::Type::Static});

  MeshSource s;
  s.kind = MeshSource::Kind::Primitive;
  s.primitive = "sphere";
  s.radius = 0.7f;
  s.segments = 128;
  s.rings = 64;
  auto sphere = std::make_shared<const TriangleMesh>(make_primitive(s, "bench"));
  std::vector<vec3> wobbled = sphere->positions;
  for (vec3& p : wobbled) p *= 1.0f + 0.25f * std::sin(9.0f * p.y) * std::cos(7.0f * p.x);
  e = reg.create();
  t = Transform{};
  t.translation = vec3(3, 1.2f, -2.5f);
  reg.emplace<Transform>(e, t);
  Material shiny;
  shiny.reflectivity = 0.5f;
  reg.emplace<Material>(e, shiny);
  Animation anim;
  anim.vertices.times = {0.0f, 1.0f, 2.0f};
  anim.vertices.values = {sphere->positions, wobbled, sphere->positions};
  reg.emplace<Mesh>(e, Mesh{sphere, s, {}, 0});
  reg.emplace<Animation>(e, std::move(anim));
  reg.emplace<Kinematics>(e, Kinematics{Kinematics::Type::Free});
  return scene;
}

std::uint64_t triangle_count(ecs::Registry& reg) {
  std::uint64_t n = 0;
  reg.view<Mesh>().each([&](ecs::Entity, const Mesh& m) { n += m.geometry->triangles.size(); });
  return n;
}

struct Run {
  std::vector<double> frame_ms, accel_ms;
  std::uint32_t restructures = 0;
  std::uint64_t rebuilt = 0, refit = 0, untouched = 0; ///< per frame, medians' inputs summed
};

/// A scene the section animates: its label, how to load it afresh (every run starts from the
/// file's state), the animation time its frames cover and its triangle count.
struct Animated {
  std::string name;
  std::function<Scene()> load;
  double duration = kDuration;
  std::uint64_t triangles = 0;
};

/// The sample and its large variant, or the --dynamic-scenes files over their own time range
/// (RenderSettings::anim_start/anim_end: AFF's `a`, JSON's settings.animation), else kDuration.
std::vector<Animated> animated_scenes(const Options& o) {
  std::vector<Animated> out;
  if (o.dynamic_scenes.empty()) {
    out = {{"dynamic_three_classes", [&o] { return sample(o); }},
           {"dynamic_three_classes + statue + wobbling sphere", [&o] { return large(o); }}};
    for (Animated& a : out) {
      Scene probe = a.load();
      a.triangles = triangle_count(probe.registry);
    }
    return out;
  }
  for (const std::string& file : split_list(o.dynamic_scenes)) {
    const fs::path path(file);
    Scene probe = load_scene(path); // a bad file fails here, before any measurement
    const double range = double(probe.settings.anim_end) - double(probe.settings.anim_start);
    out.push_back({path.filename().string(), [path] { return load_scene(path); },
                   range > 0.0 ? range : kDuration, triangle_count(probe.registry)});
  }
  return out;
}

/// `frames` frames over the scene's duration after the first build (frame 0, not measured: it
/// builds everything), Whitted at depth 2.
Run animate(const Animated& animated, const std::string& backend, std::uint32_t width,
            std::uint32_t height, int frames, int threads, bool shadows = true,
            std::uint32_t depth = 2) {
  Scene scene = animated.load();
  RenderJob job;
  job.backend = backend;
  job.settings.mode = TraceMode::Whitted;
  job.settings.max_depth = depth;
  job.settings.shadows = shadows;
  job.settings.background = scene.settings.background;
  job.settings.threads = std::uint32_t(threads);
  job.image = Framebuffer(width, height);
  prepare_rendering(scene.registry, std::move(job));
  Schedule schedule;
  schedule.tick(scene.registry, 0.0);
  Run run;
  for (int f = 0; f < frames; ++f) {
    schedule.tick(scene.registry, animated.duration / frames);
    const FrameStats& s = scene.registry.resource<RenderJob>().last;
    run.frame_ms.push_back(s.ms);
    run.accel_ms.push_back(s.systems.acceleration_ms);
    run.restructures += s.accel.restructures;
    run.rebuilt += s.accel.triangles_rebuilt;
    run.refit += s.accel.triangles_refit;
    run.untouched += s.accel.triangles_untouched;
  }
  return run;
}

fs::path report_dir(const Options& o) {
  const fs::path dir =
      o.out_dir.empty() ? fs::path(o.source_dir) / "docs/dynamic-report" : fs::path(o.out_dir);
  fs::create_directories(dir);
  return dir;
}

} // namespace

void section_dynamic(const Options& o) {
  const std::uint32_t width = std::min(512u, o.size);
  const std::uint32_t height = std::max(1u, width * 400 / 512);
  const int frames = std::max(2, o.frames);
  const fs::path dir = report_dir(o);
  Report report;
  const std::vector<Animated> scenes = animated_scenes(o);
  report("\n### Animated scenes: acceleration update against frame time (%ux%u, Whitted depth 2, "
         "%d threads, %d frames over each scene's animation after the first build)\n\n",
         width, height, o.threads, frames);
  report("| scene | triangles | backend | frame ms (median) | update ms (median) | update / frame "
         "| frames/s | restructures | triangles per frame: rebuilt / refit / untouched |\n"
         "|---|---:|---|---:|---:|---:|---:|---:|---|\n");
  const Rgb colours[] = {{31, 119, 180}, {214, 39, 40}, {44, 160, 44}};
  const Marker markers[] = {Marker::Circle, Marker::Square, Marker::TriangleUp};
  for (std::size_t i = 0; i < scenes.size(); ++i) {
    const Animated& scene = scenes[i];
    const char* name = scene.name.c_str();
    Plot plot;
    plot.title = scene.name + ": ms per frame";
    plot.x_label = "frame";
    plot.y_label = "ms";
    plot.y_min = 0.0;
    int k = 0;
    for (const char* backend : {"native", "native-bvh", "embree"}) {
      if (!backend_info(backend).available) continue;
      const Run run = animate(scene, backend, width, height, frames, o.threads);
      const double frame = median(run.frame_ms), update = median(run.accel_ms);
      report("| %s | %llu | %s | %.1f | %.2f | %.1f%% | %.1f | %u | %llu / %llu / %llu |\n", name,
             static_cast<unsigned long long>(scene.triangles), backend, frame, update,
             100.0 * update / frame, 1000.0 / frame, run.restructures,
             static_cast<unsigned long long>(run.rebuilt / std::uint64_t(frames)),
             static_cast<unsigned long long>(run.refit / std::uint64_t(frames)),
             static_cast<unsigned long long>(run.untouched / std::uint64_t(frames)));
      PlotSeries whole{{}, colours[k], markers[k]}, upd{{}, colours[k], Marker::Cross};
      for (std::size_t f = 0; f < run.frame_ms.size(); ++f) {
        whole.points.push_back({double(f + 1), run.frame_ms[f]});
        upd.points.push_back({double(f + 1), run.accel_ms[f]});
      }
      plot.series.push_back(whole);
      plot.series.push_back(upd);
      plot.legend.push_back({std::string(backend) + " frame", colours[k], markers[k]});
      plot.legend.push_back({std::string(backend) + " update", colours[k], Marker::Cross});
      ++k;
    }
    // The default scenes' plots keep their names (docs/PERFORMANCE.md links them).
    const fs::path png =
        dir / (!o.dynamic_scenes.empty() ? "frames_" + fs::path(scene.name).stem().string() + ".png"
               : i == 0                  ? std::string("frames_sample.png")
                                         : std::string("frames_large.png"));
    write_plot_png(plot, png);
    report("\nPer-frame plot: `%s`\n\n", png.filename().string().c_str());
  }

  report("\n### Table 1 of the real-time ray tracer paper on the animated scenes (%ux%u, frame "
         "ms: median of %d frames, updates included)\n\n",
         width, height, frames);
  report("| scene | configuration | BVH only (native-bvh) | kd-tree + BVH (native) | Embree | "
         "kd+BVH speed-up over BVH only |\n|---|---|---:|---:|---:|---:|\n");
  struct Config {
    const char* name;
    bool shadows;
    std::uint32_t depth;
  };
  const Config configs[] = {{"diffuse", false, 0},
                            {"+ shadows", true, 0},
                            {"+ reflection & refraction", false, 2},
                            {"all effects", true, 2}};
  for (const Animated& scene : scenes) {
    for (const Config& c : configs) {
      double ms[3] = {0, 0, 0};
      int k = 0;
      for (const char* backend : {"native-bvh", "native", "embree"}) {
        if (backend_info(backend).available)
          ms[k] =
              median(animate(scene, backend, width, height, frames, o.threads, c.shadows, c.depth)
                         .frame_ms);
        ++k;
      }
      report("| %s | %s | %.1f | %.1f | %.1f | %.2f |\n", scene.name.c_str(), c.name, ms[0], ms[1],
             ms[2], ms[1] > 0.0 ? ms[0] / ms[1] : 0.0);
    }
  }
  report.save(dir / "README.md");
}

} // namespace specula::bench
