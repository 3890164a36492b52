#pragma once
/// \file
/// A registry resource that shares geometry between entities: the same file (and glTF mesh index)
/// or the same primitive parameters give the same TriangleMesh.

#include "specula/geometry/triangle_mesh.h"
#include "specula/scene/components/mesh.h"

#include <filesystem>
#include <map>
#include <memory>
#include <tuple>

namespace specula {

class MeshLibrary {
public:
  /// The geometry for `source`; `base_dir` resolves relative file paths. Loads or generates it on
  /// first use. Throws specula::Error for unreadable files or bad primitive parameters.
  std::shared_ptr<const TriangleMesh> get(const MeshSource& source,
                                          const std::filesystem::path& base_dir);

private:
  std::map<std::tuple<std::string, int>, std::shared_ptr<const TriangleMesh>> files_;
  std::map<std::string, std::shared_ptr<const TriangleMesh>> primitives_;
};

} // namespace specula
