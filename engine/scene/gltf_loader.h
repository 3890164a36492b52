#pragma once
/// \file
/// glTF 2.0 (.gltf and .glb) through tinygltf: node hierarchy, meshes, PBR materials mapped to
/// Material, cameras, KHR_lights_punctual, animations.

#include "specula/geometry/triangle_mesh.h"
#include "specula/scene/scene.h"

#include <filesystem>

namespace specula {

/// Reads the file's default scene (or scene 0) into a Scene. Throws specula::Error naming the
/// file (and the glTF object, e.g. "meshes[2].primitives[0]") for anything malformed. Emplaces
/// no Kinematics (glTF cannot state them): load_scene infers them.
[[nodiscard]] Scene load_gltf_scene(const std::filesystem::path& path);

/// One mesh of a glTF file, all its triangle primitives merged, in the mesh's own space.
[[nodiscard]] TriangleMesh load_gltf_mesh(const std::filesystem::path& path, int mesh_index);

} // namespace specula
