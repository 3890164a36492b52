#include "scene/mesh_io.h"
#include "core/error.h"
namespace specula {
bool is_mesh_file_extension(std::string_view) { return false; }
TriangleMesh load_mesh_file(const std::filesystem::path& path) {
  throw Error(path.string(), "mesh files: not implemented yet");
}
} // namespace specula
