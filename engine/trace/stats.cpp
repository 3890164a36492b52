#include "specula/trace/stats.h"

#include "specula/core/error.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <fstream>

namespace specula {
namespace {

using nlohmann::json;

constexpr RayKind kKinds[] = {RayKind::Primary, RayKind::Shadow, RayKind::Reflection,
                              RayKind::Refraction};

template <typename T>
T read(const json& object, const char* key, const std::string& name, const std::string& path) {
  const auto it = object.find(key);
  if (it == object.end()) throw Error(name, path + "." + key, "missing");
  try {
    return it->get<T>();
  } catch (const json::exception&) {
    throw Error(name, path + "." + key, "has the wrong type");
  }
}

json cache_json(const CacheCounts& c) {
  json cubes = json::array();
  for (const CubeReport& r : c.cubes)
    cubes.push_back({{"entity", r.entity},
                     {"resolution", r.resolution},
                     {"mode", r.mode},
                     {"reason", r.reason},
                     {"lookups", r.lookups},
                     {"hits", r.hits},
                     {"valid", r.valid},
                     {"estimated_psnr_db", r.estimated_psnr_db},
                     {"saved_ms", r.saved_ms}});
  return {{"lookups", c.lookups},     {"hits", c.hits},
          {"rejected", c.rejected},   {"verified", c.verified},
          {"written", c.written},     {"prefilled", c.prefilled},
          {"texels", c.texels},       {"valid", c.valid},
          {"invalidated", c.invalidated}, {"flush_all", c.flush_all},
          {"memory_bytes", c.memory_bytes}, {"cubes", cubes}};
}

template <typename T> void read_optional(const json& o, const char* key, T& value,
                                         const std::string& name, const std::string& path) {
  if (o.contains(key)) value = read<T>(o, key, name, path);
}

} // namespace

const char* gpu_stage_name(GpuStage stage) {
  switch (stage) {
  case GpuStage::Eye:
    return "eye";
  case GpuStage::Visibility:
    return "visibility";
  case GpuStage::Trace:
    return "trace";
  case GpuStage::Shade:
    return "shade";
  case GpuStage::Shadow:
    return "shadow";
  case GpuStage::Fold:
    return "fold";
  }
  return "?";
}

const char* ray_kind_name(RayKind kind) {
  switch (kind) {
  case RayKind::Primary:
    return "primary";
  case RayKind::Shadow:
    return "shadow";
  case RayKind::Reflection:
    return "reflection";
  case RayKind::Refraction:
    return "refraction";
  }
  return "unknown";
}

std::uint64_t RayCounts::total() const {
  std::uint64_t t = 0;
  for (const std::uint64_t c : count) t += c;
  return t;
}

RayCounts& RayCounts::operator+=(const RayCounts& o) {
  for (int i = 0; i < kRayKindCount; ++i) count[i] += o.count[i];
  dropped += o.dropped;
  nonfinite += o.nonfinite;
  return *this;
}

double median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const std::size_t h = values.size() / 2;
  return values.size() % 2 ? values[h] : 0.5 * (values[h - 1] + values[h]);
}

std::string stats_to_json(const RunStats& stats) {
  const RunSettings& s = stats.settings;
  json settings = {{"scene", s.scene},
                   {"backend", s.backend},
                   {"mode", s.mode},
                   {"width", s.width},
                   {"height", s.height},
                   {"frames", s.frames},
                   {"time0", s.time0},
                   {"time1", s.time1},
                   {"threads", s.threads},
                   {"max_depth", s.max_depth},
                   {"cache", s.cache_policy == "off" ? json("off")
                                                     : json{{"policy", s.cache_policy},
                                                            {"lookup", s.cache_lookup},
                                                            {"tau_deg", s.cache_tau_deg},
                                                            {"resolution", s.cache_resolution},
                                                            {"fill_budget", s.cache_fill_budget},
                                                            {"prefill", s.cache_prefill},
                                                            {"fill_ahead", s.cache_fill_ahead},
                                                            {"samples", s.cache_samples},
                                                            {"refresh", s.cache_refresh},
                                                            {"irradiance", s.cache_irradiance},
                                                            {"serve", s.cache_serve},
                                                            {"max_error_db", s.max_error_db}}},
                   {"spp", s.spp},
                   {"shadow_samples", s.shadow_samples},
                   {"sampling", s.sampling},
                   {"seed", s.seed},
                   {"accumulate", s.accumulate},
                   {"denoise", s.denoise ? json{{"iterations", s.denoise_iterations},
                                                {"sigma_color", s.denoise_sigma_color},
                                                {"sigma_normal", s.denoise_sigma_normal},
                                                {"sigma_depth", s.denoise_sigma_depth},
                                                {"sigma_variance", s.denoise_sigma_variance}}
                                         : json(false)}};
  if (!s.gpu_device.empty())
    settings["gpu"] = {{"device", s.gpu_device},
                       {"device_type", s.gpu_device_type},
                       {"execution", s.gpu_execution},
                       {"primary", s.gpu_primary},
                       {"device_frames", s.gpu_device_frames},
                       {"grid_density", s.grid_density}};
  json frames = json::array();
  double total_ms = 0.0;
  double total_trace_ms = 0.0;
  RayCounts total_rays;
  CacheCounts total_cache;
  for (const FrameStats& f : stats.frames) {
    json rays = json::object();
    json rates = json::object();
    for (const RayKind k : kKinds) {
      rays[ray_kind_name(k)] = f.rays[k];
      rates[ray_kind_name(k)] = f.trace_ms > 0.0 ? double(f.rays[k]) / (f.trace_ms * 1e3) : 0.0;
    }
    rates["total"] = f.trace_ms > 0.0 ? double(f.rays.total()) / (f.trace_ms * 1e3) : 0.0;
    frames.push_back({{"time", f.time},
                      {"ms", f.ms},
                      {"trace_ms", f.trace_ms},
                      {"rays", rays},
                      {"dropped_rays", f.rays.dropped},
                      {"nonfinite_samples", f.rays.nonfinite},
                      {"mrays_per_s", rates},
                      {"cache", cache_json(f.cache)},
                      {"accel",
                       {{"ms", f.accel.ms},
                        {"static_build_ms", f.accel.static_build_ms},
                        {"blas_build_ms", f.accel.blas_build_ms},
                        {"refit_ms", f.accel.refit_ms},
                        {"restructure_ms", f.accel.restructure_ms},
                        {"top_build_ms", f.accel.top_build_ms},
                        {"static_builds", f.accel.static_builds},
                        {"blas_builds", f.accel.blas_builds},
                        {"refits", f.accel.refits},
                        {"restructures", f.accel.restructures},
                        {"hidden_instances", f.accel.hidden_instances},
                        {"triangles_rebuilt", f.accel.triangles_rebuilt},
                        {"triangles_refit", f.accel.triangles_refit},
                        {"triangles_untouched", f.accel.triangles_untouched}}},
                      {"systems_ms",
                       {{"animation", f.systems.animation_ms},
                        {"transform", f.systems.transform_ms},
                        {"scene_layer", f.systems.scene_layer_ms},
                        {"acceleration", f.systems.acceleration_ms},
                        {"cache_invalidation", f.systems.cache_invalidation_ms},
                        {"render", f.systems.render_ms}}},
                      {"accumulated_samples", f.accumulated_samples},
                      {"accumulation_restarted", f.accumulation_restarted},
                      {"denoise_ms", f.denoise_ms}});
    if (f.gpu.present) {
      frames.back()["gpu"] = {{"rays", f.gpu.rays},     {"resumed", f.gpu.resumed},
                              {"cut", f.gpu.cut},       {"dispatches", f.gpu.dispatches},
                              {"gpu_ms", f.gpu.gpu_ms}, {"submits", f.gpu.submits}};
      if (f.gpu.stage_ms != GpuStageTimes{}) {
        json stages = json::object();
        for (int k = 0; k < kGpuStageCount; ++k)
          stages[gpu_stage_name(GpuStage(k))] = f.gpu.stage_ms[std::size_t(k)];
        frames.back()["gpu"]["stages_ms"] = stages;
      }
    }
    total_ms += f.ms;
    total_trace_ms += f.trace_ms;
    total_rays += f.rays;
    total_cache.lookups += f.cache.lookups;
    total_cache.hits += f.cache.hits;
  }
  std::vector<double> ms;
  for (const FrameStats& f : stats.frames) ms.push_back(f.ms);
  json summary = {
      {"frames", stats.frames.size()},
      {"total_ms", total_ms},
      {"median_ms", median(ms)},
      {"rays", total_rays.total()},
      {"mrays_per_s",
       total_trace_ms > 0.0 ? double(total_rays.total()) / (total_trace_ms * 1e3) : 0.0},
      {"cache_hit_rate",
       total_cache.lookups > 0 ? double(total_cache.hits) / double(total_cache.lookups) : 0.0},
      {"accumulated_samples", stats.frames.empty() ? 0 : stats.frames.back().accumulated_samples}};
  return json{{"settings", settings}, {"frames", frames}, {"summary", summary}}.dump(2) + "\n";
}

RunStats stats_from_json(const std::string& text, const std::string& name) {
  json root;
  try {
    root = json::parse(text);
  } catch (const json::parse_error& e) {
    throw Error(name, std::string("malformed JSON: ") + e.what());
  }
  if (!root.is_object()) throw Error(name, "the stats file must hold a JSON object");
  RunStats stats;
  const json settings = read<json>(root, "settings", name, "");
  RunSettings& s = stats.settings;
  s.scene = read<std::string>(settings, "scene", name, "settings");
  s.backend = read<std::string>(settings, "backend", name, "settings");
  s.mode = read<std::string>(settings, "mode", name, "settings");
  s.width = read<std::uint32_t>(settings, "width", name, "settings");
  s.height = read<std::uint32_t>(settings, "height", name, "settings");
  s.frames = read<std::uint32_t>(settings, "frames", name, "settings");
  // Arrived with animated rendering (issue 11): older files have none.
  read_optional(settings, "time0", s.time0, name, "settings");
  read_optional(settings, "time1", s.time1, name, "settings");
  s.threads = read<std::uint32_t>(settings, "threads", name, "settings");
  s.max_depth = read<std::uint32_t>(settings, "max_depth", name, "settings");
  const json cache = read<json>(settings, "cache", name, "settings");
  if (cache.is_object()) {
    const std::string at = "settings.cache";
    s.cache_policy = read<std::string>(cache, "policy", name, at);
    s.cache_lookup = read<std::string>(cache, "lookup", name, at);
    s.cache_tau_deg = read<float>(cache, "tau_deg", name, at);
    s.cache_resolution = read<std::uint32_t>(cache, "resolution", name, at);
    s.cache_fill_budget = read<std::uint32_t>(cache, "fill_budget", name, at);
    s.cache_prefill = read<bool>(cache, "prefill", name, at);
    read_optional(cache, "fill_ahead", s.cache_fill_ahead, name, at); // arrived later
    read_optional(cache, "samples", s.cache_samples, name, at);
    read_optional(cache, "refresh", s.cache_refresh, name, at);
    read_optional(cache, "irradiance", s.cache_irradiance, name, at); // these two arrived
    read_optional(cache, "serve", s.cache_serve, name, at);           // later
    s.max_error_db = read<double>(cache, "max_error_db", name, at);
  } else if (!cache.is_string()) {
    // Files from before the cubes landed gave a bare resolution.
    s.cache_resolution = read<std::uint32_t>(settings, "cache", name, "settings");
    s.cache_policy = s.cache_resolution == 0 ? "off" : "auto";
  }
  // The stochastic modes' settings arrived with issue 9: older files have none.
  read_optional(settings, "spp", s.spp, name, "settings");
  read_optional(settings, "shadow_samples", s.shadow_samples, name, "settings");
  read_optional(settings, "sampling", s.sampling, name, "settings");
  read_optional(settings, "seed", s.seed, name, "settings");
  read_optional(settings, "accumulate", s.accumulate, name, "settings");
  if (settings.contains("denoise")) {
    const json denoise = settings.at("denoise");
    if (denoise.is_object()) {
      const std::string at = "settings.denoise";
      s.denoise = true;
      s.denoise_iterations = read<std::uint32_t>(denoise, "iterations", name, at);
      s.denoise_sigma_color = read<float>(denoise, "sigma_color", name, at);
      s.denoise_sigma_normal = read<float>(denoise, "sigma_normal", name, at);
      s.denoise_sigma_depth = read<float>(denoise, "sigma_depth", name, at);
      // Arrived with the variance-guided colour weight (2026-11-28).
      read_optional(denoise, "sigma_variance", s.denoise_sigma_variance, name, at);
    } else if (denoise != json(false)) {
      throw Error(name, "settings.denoise", "must be false or an object");
    }
  }
  // Arrived with the Vulkan path (issue 10): CPU runs and older files have none.
  if (settings.contains("gpu")) {
    const json g = read<json>(settings, "gpu", name, "settings");
    const std::string at = "settings.gpu";
    s.gpu_device = read<std::string>(g, "device", name, at);
    s.gpu_device_type = read<std::string>(g, "device_type", name, at);
    s.gpu_execution = read<std::string>(g, "execution", name, at);
    // Arrived with hybrid mode: older files traced their primary rays.
    if (g.contains("primary")) s.gpu_primary = read<std::string>(g, "primary", name, at);
    s.gpu_device_frames = read<bool>(g, "device_frames", name, at);
    s.grid_density = read<float>(g, "grid_density", name, at);
  }
  const json frames = read<json>(root, "frames", name, "");
  if (!frames.is_array()) throw Error(name, "frames", "must be an array");
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const std::string at = "frames[" + std::to_string(i) + "]";
    FrameStats f;
    f.ms = read<double>(frames[i], "ms", name, at);
    f.trace_ms = read<double>(frames[i], "trace_ms", name, at);
    const json rays = read<json>(frames[i], "rays", name, at);
    for (const RayKind k : kKinds)
      f.rays[k] = read<std::uint64_t>(rays, ray_kind_name(k), name, at + ".rays");
    f.rays.dropped = read<std::uint64_t>(frames[i], "dropped_rays", name, at);
    // Arrived with issue 13 (non-finite radiance written as 0): older files have none.
    read_optional(frames[i], "nonfinite_samples", f.rays.nonfinite, name, at);
    const json c = read<json>(frames[i], "cache", name, at);
    f.cache.lookups = read<std::uint64_t>(c, "lookups", name, at + ".cache");
    f.cache.hits = read<std::uint64_t>(c, "hits", name, at + ".cache");
    // The rest arrived with the ray-cache cubes: files written before them have none.
    const std::string ca = at + ".cache";
    read_optional(c, "rejected", f.cache.rejected, name, ca);
    read_optional(c, "verified", f.cache.verified, name, ca);
    read_optional(c, "written", f.cache.written, name, ca);
    read_optional(c, "prefilled", f.cache.prefilled, name, ca);
    read_optional(c, "texels", f.cache.texels, name, ca);
    read_optional(c, "valid", f.cache.valid, name, ca);
    read_optional(c, "invalidated", f.cache.invalidated, name, ca);
    read_optional(c, "flush_all", f.cache.flush_all, name, ca);
    read_optional(c, "memory_bytes", f.cache.memory_bytes, name, ca);
    if (c.contains("cubes")) {
      const json cubes = read<json>(c, "cubes", name, ca);
      if (!cubes.is_array()) throw Error(name, ca + ".cubes", "must be an array");
      for (std::size_t k = 0; k < cubes.size(); ++k) {
        const std::string w = ca + ".cubes[" + std::to_string(k) + "]";
        CubeReport r;
        r.entity = read<std::uint32_t>(cubes[k], "entity", name, w);
        r.resolution = read<std::uint32_t>(cubes[k], "resolution", name, w);
        r.mode = read<std::string>(cubes[k], "mode", name, w);
        r.reason = read<std::string>(cubes[k], "reason", name, w);
        r.lookups = read<std::uint64_t>(cubes[k], "lookups", name, w);
        r.hits = read<std::uint64_t>(cubes[k], "hits", name, w);
        r.valid = read<std::uint64_t>(cubes[k], "valid", name, w);
        r.estimated_psnr_db = read<double>(cubes[k], "estimated_psnr_db", name, w);
        r.saved_ms = read<double>(cubes[k], "saved_ms", name, w);
        f.cache.cubes.push_back(r);
      }
    }
    // "accel" arrived with the native backend: files written before it have none.
    if (frames[i].contains("accel")) {
      const json a = read<json>(frames[i], "accel", name, at);
      const std::string where = at + ".accel";
      f.accel.ms = read<double>(a, "ms", name, where);
      f.accel.static_build_ms = read<double>(a, "static_build_ms", name, where);
      f.accel.blas_build_ms = read<double>(a, "blas_build_ms", name, where);
      f.accel.refit_ms = read<double>(a, "refit_ms", name, where);
      f.accel.restructure_ms = read<double>(a, "restructure_ms", name, where);
      f.accel.top_build_ms = read<double>(a, "top_build_ms", name, where);
      f.accel.static_builds = read<std::uint32_t>(a, "static_builds", name, where);
      f.accel.blas_builds = read<std::uint32_t>(a, "blas_builds", name, where);
      f.accel.refits = read<std::uint32_t>(a, "refits", name, where);
      f.accel.restructures = read<std::uint32_t>(a, "restructures", name, where);
      // Arrived with issue 13's degenerate-instance handling: older files have none.
      read_optional(a, "hidden_instances", f.accel.hidden_instances, name, where);
      // Arrived with issue 11's coherence counts: older files have none.
      read_optional(a, "triangles_rebuilt", f.accel.triangles_rebuilt, name, where);
      read_optional(a, "triangles_refit", f.accel.triangles_refit, name, where);
      read_optional(a, "triangles_untouched", f.accel.triangles_untouched, name, where);
    }
    // Per frame scene time and per-system times arrived with issue 11: older files have none.
    read_optional(frames[i], "time", f.time, name, at);
    if (frames[i].contains("systems_ms")) {
      const json y = read<json>(frames[i], "systems_ms", name, at);
      const std::string where = at + ".systems_ms";
      SystemTimes& t = f.systems;
      t.animation_ms = read<double>(y, "animation", name, where);
      t.transform_ms = read<double>(y, "transform", name, where);
      t.scene_layer_ms = read<double>(y, "scene_layer", name, where);
      t.acceleration_ms = read<double>(y, "acceleration", name, where);
      t.cache_invalidation_ms = read<double>(y, "cache_invalidation", name, where);
      t.render_ms = read<double>(y, "render", name, where);
    }
    // Arrived with issue 9's accumulation: older files have none.
    read_optional(frames[i], "accumulated_samples", f.accumulated_samples, name, at);
    read_optional(frames[i], "accumulation_restarted", f.accumulation_restarted, name, at);
    read_optional(frames[i], "denoise_ms", f.denoise_ms, name, at);
    if (frames[i].contains("gpu")) {
      const json g = read<json>(frames[i], "gpu", name, at);
      const std::string where = at + ".gpu";
      f.gpu.present = true;
      f.gpu.rays = read<std::uint64_t>(g, "rays", name, where);
      f.gpu.resumed = read<std::uint64_t>(g, "resumed", name, where);
      f.gpu.cut = read<std::uint64_t>(g, "cut", name, where);
      f.gpu.dispatches = read<std::uint64_t>(g, "dispatches", name, where);
      f.gpu.gpu_ms = read<double>(g, "gpu_ms", name, where);
      // Arrived 2026-11-29: older files have none.
      read_optional(g, "submits", f.gpu.submits, name, where);
      if (g.contains("stages_ms")) {
        const json stages = read<json>(g, "stages_ms", name, where);
        for (int k = 0; k < kGpuStageCount; ++k)
          f.gpu.stage_ms[std::size_t(k)] =
              read<double>(stages, gpu_stage_name(GpuStage(k)), name, where + ".stages_ms");
      }
    }
    stats.frames.push_back(f);
  }
  return stats;
}

void write_stats_file(const RunStats& stats, const std::filesystem::path& path) {
  std::ofstream out(path, std::ios::binary);
  if (!out) throw Error(path.string(), "cannot open the stats file for writing");
  out << stats_to_json(stats);
  if (!out.flush()) throw Error(path.string(), "cannot write the stats file");
}

} // namespace specula
