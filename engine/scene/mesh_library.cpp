#include "specula/scene/mesh_library.h"

#include "specula/core/error.h"
#include "specula/geometry/primitives.h"
#include "specula/scene/gltf_loader.h"
#include "specula/scene/mesh_io.h"

#include <sstream>

namespace specula {
namespace {

std::string primitive_key(const MeshSource& s) {
  std::ostringstream key;
  key.precision(9);
  key << s.primitive << '|' << s.size.x << ',' << s.size.y << ',' << s.size.z << '|' << s.radius
      << '|' << s.height << '|' << s.segments << '|' << s.rings << '|' << s.top_radius;
  return key.str();
}

} // namespace

std::shared_ptr<const TriangleMesh> MeshLibrary::get(const MeshSource& source,
                                                     const std::filesystem::path& base_dir) {
  switch (source.kind) {
  case MeshSource::Kind::Primitive: {
    const std::string key = primitive_key(source);
    auto& slot = primitives_[key];
    if (!slot) slot = std::make_shared<const TriangleMesh>(make_primitive(source, source.primitive));
    return slot;
  }
  case MeshSource::Kind::File: {
    const std::filesystem::path resolved =
        std::filesystem::path(source.path).is_absolute() ? std::filesystem::path(source.path)
                                                          : base_dir / source.path;
    auto& slot = files_[{resolved.lexically_normal().string(), source.gltf_mesh}];
    if (!slot) {
      std::string ext = resolved.extension().string();
      for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      TriangleMesh mesh;
      if (ext == ".gltf" || ext == ".glb")
        mesh = load_gltf_mesh(resolved, source.gltf_mesh < 0 ? 0 : source.gltf_mesh);
      else
        mesh = load_mesh_file(resolved);
      slot = std::make_shared<const TriangleMesh>(std::move(mesh));
    }
    return slot;
  }
  case MeshSource::Kind::Inline:
    break;
  }
  throw Error(source.path, "inline meshes are not stored in the mesh library");
}

} // namespace specula
