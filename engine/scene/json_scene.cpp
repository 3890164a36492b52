#include "scene/json_scene.h"
#include "core/error.h"
namespace specula {
Scene load_json_scene(const std::filesystem::path& path) {
  throw Error(path.string(), "JSON scenes: not implemented yet");
}
Scene parse_json_scene(const std::string&, const std::string& name, const std::filesystem::path&) {
  throw Error(name, "JSON scenes: not implemented yet");
}
std::string write_json_scene(Scene&) { throw Error("JSON scenes: not implemented yet"); }
void save_json_scene(Scene&, const std::filesystem::path& path) {
  throw Error(path.string(), "JSON scenes: not implemented yet");
}
} // namespace specula
