#pragma once
/// \file
/// Bare mesh files (OBJ, PLY, OFF, STL) through OpenMesh.

#include "specula/geometry/triangle_mesh.h"

#include <filesystem>
#include <string_view>

namespace specula {

/// Whether load_mesh_file reads files with this extension (".obj", ".ply", ".off", ".stl",
/// case-insensitive).
[[nodiscard]] bool is_mesh_file_extension(std::string_view extension);

/// Reads one triangle mesh (polygons are triangulated). Throws specula::Error naming the file for
/// a missing or unreadable file, an unknown extension, malformed or truncated content, NaN/Inf
/// values, out-of-range indices, or no triangles.
[[nodiscard]] TriangleMesh load_mesh_file(const std::filesystem::path& path);

} // namespace specula
