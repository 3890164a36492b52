#include "specula/geometry/triangle_mesh.h"

#include "specula/core/error.h"

namespace specula {

Aabb TriangleMesh::bounds() const {
  Aabb box;
  for (const vec3& p : positions) box.grow(p);
  return box;
}

void TriangleMesh::validate(const std::string& source) const {
  if (triangles.empty()) throw Error(source, "mesh has no triangles");
  if (!normals.empty() && normals.size() != positions.size())
    throw Error(source, "mesh has " + std::to_string(normals.size()) + " normals for " +
                            std::to_string(positions.size()) + " vertices");
  if (!uvs.empty() && uvs.size() != positions.size())
    throw Error(source, "mesh has " + std::to_string(uvs.size()) + " texture coordinates for " +
                            std::to_string(positions.size()) + " vertices");
  for (std::size_t i = 0; i < positions.size(); ++i) {
    if (!is_finite(positions[i]))
      throw Error(source, "vertex " + std::to_string(i) + " has a non-finite position (NaN or Inf)");
    if (!in_range(positions[i]))
      throw Error(source, "vertex " + std::to_string(i) + " has a coordinate outside " +
                              kCoordinateRangeText);
  }
  for (std::size_t i = 0; i < normals.size(); ++i)
    if (!is_finite(normals[i]))
      throw Error(source, "vertex " + std::to_string(i) + " has a non-finite normal (NaN or Inf)");
  for (std::size_t i = 0; i < uvs.size(); ++i)
    if (!is_finite(uvs[i]))
      throw Error(source, "vertex " + std::to_string(i) +
                              " has a non-finite texture coordinate (NaN or Inf)");
  const auto n = static_cast<std::uint32_t>(positions.size());
  for (std::size_t t = 0; t < triangles.size(); ++t)
    for (int k = 0; k < 3; ++k)
      if (triangles[t][k] >= n)
        throw Error(source, "triangle " + std::to_string(t) + " uses vertex index " +
                                std::to_string(triangles[t][k]) + " but the mesh has only " +
                                std::to_string(n) + " vertices");
}

void TriangleMesh::compute_vertex_normals() {
  normals.assign(positions.size(), vec3(0.0f));
  for (const uvec3& t : triangles) {
    const vec3 n = glm::cross(positions[t.y] - positions[t.x], positions[t.z] - positions[t.x]);
    normals[t.x] += n;
    normals[t.y] += n;
    normals[t.z] += n;
  }
  for (vec3& n : normals) {
    const float len = glm::length(n);
    n = len > 0.0f && std::isfinite(len) ? n / len : vec3(0, 0, 1);
  }
}

} // namespace specula
