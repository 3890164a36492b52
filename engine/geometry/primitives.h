#pragma once
/// \file
/// Built-in primitives for scene files: sphere, box, plane, cylinder, cone, with the tessellation
/// given in MeshSource. Centred at the origin, +Y up, outward-facing counter-clockwise triangles,
/// smooth normals on curved surfaces and flat normals on flat faces, UVs.

#include "specula/geometry/triangle_mesh.h"
#include "specula/scene/components/mesh.h"

#include <string>

namespace specula {

/// Generates source.primitive with source's parameters. Throws specula::Error(context, ...) for
/// an unknown name, non-finite or non-positive sizes, or tessellation outside [3, 4096]
/// (segments) / [2, 4096] (sphere rings) / [1, 4096] (plane subdivisions).
[[nodiscard]] TriangleMesh make_primitive(const MeshSource& source, const std::string& context);

} // namespace specula
