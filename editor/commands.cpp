#include "commands.h"

#include "core/error.h"
#include "scene/scene.h"
#include "trace/stats.h"

#include <nlohmann/json.hpp>

#include <charconv>
#include <ostream>

namespace specula::cli {
namespace {

nlohmann::json vec_json(const vec3& v) { return {v.x, v.y, v.z}; }

/// "off" → 0; otherwise a power of two in [1, 4096].
std::uint32_t parse_cache(const std::string& text) {
  if (text == "off") return 0;
  std::uint32_t value = 0;
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (ec != std::errc{} || end != text.data() + text.size() || value == 0 || value > 4096 ||
      (value & (value - 1)) != 0)
    throw Error("--cache", "expected 'off' or a power of two from 1 to 4096, got '" + text + "'");
  return value;
}

} // namespace

int run_info(const InfoOptions& options, std::ostream& out) {
  Scene scene = load_scene(options.scene);
  const SceneSummary s = summarize(scene);
  if (options.json) {
    nlohmann::json j = {{"scene", options.scene},
                        {"entities", s.entities},
                        {"mesh_entities", s.mesh_entities},
                        {"unique_meshes", s.unique_meshes},
                        {"triangles", s.triangles},
                        {"materials", s.materials},
                        {"lights", s.lights},
                        {"cameras", s.cameras},
                        {"reflective", s.reflective},
                        {"refractive", s.refractive},
                        {"ray_cache_cubes", s.ray_cache_cubes},
                        {"animated", s.animated},
                        {"settings", {{"width", scene.settings.width},
                                      {"height", scene.settings.height},
                                      {"max_depth", scene.settings.max_depth}}}};
    if (!s.bounds.empty()) j["bounds"] = {{"min", vec_json(s.bounds.min)}, {"max", vec_json(s.bounds.max)}};
    out << j.dump(2) << "\n";
    return 0;
  }
  out << "scene:      " << options.scene << "\n"
      << "entities:   " << s.entities << " (" << s.mesh_entities << " with meshes, " << s.unique_meshes
      << " distinct meshes, " << s.animated << " animated)\n"
      << "triangles:  " << s.triangles << "\n"
      << "materials:  " << s.materials << " (" << s.reflective << " reflective, " << s.refractive
      << " refractive entities)\n"
      << "lights:     " << s.lights << "\n"
      << "cameras:    " << s.cameras << "\n"
      << "ray caches: " << s.ray_cache_cubes << "\n"
      << "image:      " << scene.settings.width << "x" << scene.settings.height << "\n";
  if (s.bounds.empty()) {
    out << "bounds:     empty\n";
  } else {
    out << "bounds:     min (" << s.bounds.min.x << ", " << s.bounds.min.y << ", " << s.bounds.min.z
        << ") max (" << s.bounds.max.x << ", " << s.bounds.max.y << ", " << s.bounds.max.z << ")\n";
  }
  return 0;
}

int run_render(const RenderOptions& options, std::ostream& /*out*/) {
  // Validate everything the user gave before reporting what is missing from this build, so a bad
  // scene or option is reported as such (exit 1) rather than hidden behind "not available".
  RunSettings settings;
  settings.cache_resolution = parse_cache(options.cache);
  Scene scene = load_scene(options.scene);
  settings.scene = options.scene;
  settings.backend = options.backend;
  settings.mode = options.mode;
  settings.width = options.width ? options.width : scene.settings.width;
  settings.height = options.height ? options.height : scene.settings.height;
  settings.frames = options.frames;
  settings.threads = options.threads;
  settings.max_depth = scene.settings.max_depth;
  throw UnavailableError("backend '" + options.backend + "' with mode '" + options.mode +
                         "' is not available yet in this build (the tracers land with the CPU "
                         "and Vulkan ray tracing work)");
}

} // namespace specula::cli
